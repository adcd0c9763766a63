"""What the viewer tells the user, and how: notifications in the browser, in the user's terms.

Every hint, result and error is a notification in the top-left corner of the page: one appears
while a stroke is extracted (with a spinner) and turns into the result, and a failure that happens
twice shows twice. Messages speak of what the user did (the stroke, a rod, a ball), never of the
internal render a stroke is traced on.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Any, Literal

import viser

from ..errors import SketchRodGSError

logger = logging.getLogger("sketchrodgs")

Kind = Literal["info", "busy", "done", "error"]
COLOURS: dict[Kind, Any] = {"info": "blue", "busy": "blue", "done": "green", "error": "red"}
SECONDS: dict[Kind, float | None] = {"info": 5.0, "busy": None, "done": 6.0, "error": 12.0}

# What the path search reports, said in terms of the stroke the user drew (the messages of
# rust/sketchrodgs-path and extract.py speak of the render's pixels and of CLI options).
FAILURES = (
    ("on background", "The stroke is on the background: draw it over the object."),
    ("meets an object at only", "The stroke barely touches an object: draw it along the part, from end to end."),
    ("needs at least 2 distinct points", "The stroke is too short: drag along the part, from end to end."),
    ("single point", "The stroke is a single point: drag along the part, from end to end."),
    ("not its edge", "The stroke runs along the part's edge: draw it along the part's middle."),
    (
        "runs across the stroke",
        "The part could not be followed under the stroke: something hides it there, or the stroke runs "
        "over two parts. Draw along where the part is seen.",
    ),
    (
        "too short for a rod",
        "The part under the stroke is too short for a rod: draw along more of it, or set a smaller "
        "radius R under Sketch settings.",
    ),
)


def describe_failure(error: BaseException) -> str:
    """Why a stroke made no rod, for the user who drew it."""
    text = str(error)
    if isinstance(error, SketchRodGSError):
        for key, message in FAILURES:
            if key in text:
                return message
        return text[:1].upper() + text[1:] + ("" if text.endswith(".") else ".")
    return "Something went wrong while extracting the rod (a bug: the terminal shows the details)."


@dataclass(frozen=True)
class Message:
    """A message as shown: its kind, title and body."""

    kind: Kind
    title: str
    body: str


class Notice:
    """A notification shown on one or several tabs, which can change (a spinner turning into the
    result)."""

    def __init__(self, server: viser.ViserServer, handles: list[tuple[int, Any]]) -> None:
        self._server = server
        self._handles = handles  # (the tab's client id, its notification)

    def update(self, kind: Kind, title: str, body: str) -> None:
        open_tabs = self._server.get_clients()
        for client_id, handle in self._handles:
            if client_id not in open_tabs:
                continue  # closed since: viser would queue the change and warn that it never arrives
            try:
                handle.title, handle.body = title, body
                handle.loading = kind == "busy"
                handle.color = COLOURS[kind]
                handle.auto_close_seconds = SECONDS[kind]
            except Exception:  # the tab closed meanwhile
                continue


class Feedback:
    """Sends notifications to the browser tabs.

    Args:
        server: the viser server.

    Attributes:
        last: the last message sent (to any tab), for tests and logs.
    """

    def __init__(self, server: viser.ViserServer) -> None:
        self.server = server
        self.last: Message | None = None
        self._lock = threading.Lock()

    def notify(self, client: Any, kind: Kind, title: str, body: str = "") -> Notice:
        """Show a notification on `client`'s tab (every tab when None)."""
        with self._lock:
            self.last = Message(kind, title, body)
        clients = [client] if client is not None else list(self.server.get_clients().values())
        handles = []
        for c in clients:
            try:
                handle = c.add_notification(
                    title,
                    body,
                    loading=kind == "busy",
                    with_close_button=True,
                    auto_close_seconds=SECONDS[kind],
                    color=COLOURS[kind],
                )
            except Exception:  # the tab closed meanwhile
                continue
            handles.append((c.client_id, handle))
        if kind == "error":
            logger.info("%s %s", title, body)
        return Notice(self.server, handles)

    def update(self, notice: Notice, kind: Kind, title: str, body: str = "") -> None:
        """Change what `notice` says."""
        with self._lock:
            self.last = Message(kind, title, body)
        notice.update(kind, title, body)
