//! Whole-buffer gzip inflation with libdeflate, split over the cores for big streams.
//!
//! The caller knows how many bytes the stream should hold and passes a buffer of that size, so
//! a stream that expands further (a gzip bomb, or a count that disagrees with the data) stops as
//! soon as the buffer is full.
//!
//! One deflate stream is sequential by nature, and libdeflate inflates it at about 350-450 MB/s
//! here; a million SPZ splats with SH degree 3 are 65 MB. Big streams are therefore cut into one
//! part per core, in the way of pugz and rapidgzip. The first part (the head) is libdeflate from
//! the start. Each later part looks for a block start past its share of the compressed bits and
//! decodes from there with markers for the unknown 32 KiB window (`deflate`) until its last
//! 32 KiB are marker-free, or, for the second part, until the head is done and its last 32 KiB
//! fill the markers in; it then hands the rest of its share to libdeflate behind a made-up block
//! that replays those 32 KiB as the window. Each share ends in a made-up final block at the next
//! part's start. The parts are joined, the markers filled in from the bytes before each part,
//! and the member's CRC and length checked. Anything unexpected (no block start found, a CRC
//! mismatch, bytes after the member) falls back to one sequential libdeflate call, whose verdict
//! stands.
//!
//! In streams of few distinct bytes (SPZ's SH rounded to 4-5 bits, as the reference writer does)
//! markers are copied along for megabytes, and the marker decoder runs at about 0.7 of
//! libdeflate's speed. There the second part first probes its start; when markers outlive the
//! probe it moves its start further into its share and the head, which has the real window,
//! inflates the gap with libdeflate, so that the slower decoder gets less of the stream.

use std::ops::Range;
use std::sync::{Mutex, OnceLock};

use libdeflater::{DecompressionError, Decompressor};
use rayon::prelude::*;

use crate::deflate::{self, BitWriter, Limit, WINDOW};
use crate::pages::FreshBytes;

/// Compressed bytes per part below which a stream is inflated in one piece.
const PART_MIN_BYTES: usize = 1 << 20;

/// Why a gzip member could not be inflated into the buffer given.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum GunzipError {
    #[error("corrupt gzip stream (bad data or checksum, or cut short)")]
    Corrupt,
    #[error("gzip stream holds more than the {0} bytes expected")]
    TooLong(usize),
}

/// Inflate the first gzip member of `raw` into `out`; the number of bytes written.
/// The member's CRC and length are checked; bytes after it are ignored.
pub fn gunzip_into(raw: &[u8], out: &mut [u8]) -> Result<usize, GunzipError> {
    let parts = rayon::current_num_threads().min(raw.len() / PART_MIN_BYTES);
    if parts >= 2
        && let Some(joined) = gunzip_in_parts(raw, out, parts, Schedule::Parallel)
    {
        return Ok(joined.written);
    }
    Decompressor::new().gzip_decompress(raw, out).map_err(|error| match error {
        DecompressionError::InsufficientSpace => GunzipError::TooLong(out.len()),
        DecompressionError::BadData => GunzipError::Corrupt,
    })
}

/// How a split inflation went.
#[derive(Debug, PartialEq, Eq)]
struct Joined {
    /// bytes written
    written: usize,
    /// whether the second part moved its start later (and the head inflated the gap)
    second_part_moved: bool,
}

/// When the head and the later parts run.
#[derive(Clone, Copy)]
enum Schedule {
    Parallel,
    /// one after the other, to test each outcome of the handover
    #[cfg(test)]
    HeadFirst,
    #[cfg(test)]
    SecondPartFirst,
}

/// Inflate in `parts` pieces in parallel; None where that cannot be done or checked (the caller
/// then inflates in one piece).
fn gunzip_in_parts(raw: &[u8], out: &mut [u8], parts: usize, schedule: Schedule) -> Option<Joined> {
    let start = deflate_start(raw)?;
    let trailer = raw.len().checked_sub(8).filter(|&t| t > start)?;
    let data = &raw[start..trailer];
    let word = |at: usize| u32::from_le_bytes([raw[at], raw[at + 1], raw[at + 2], raw[at + 3]]);
    let (crc, size) = (word(trailer), word(trailer + 4) as usize);
    if size > out.len() {
        return None;
    }
    // Part i starts at the first block boundary past i/parts of the compressed bits; where its
    // share holds none (stored blocks only, say), the part before takes over its share.
    let bits = 8 * data.len();
    let starts: Vec<deflate::Found> = (1..parts)
        .into_par_iter()
        .filter_map(|i| deflate::find_block(data, bits * i / parts, bits * (i + 1) / parts))
        .collect();
    let first = starts.first()?.start;
    let ends: Vec<usize> = starts.iter().skip(1).map(|found| found.start).chain([bits]).collect();
    let last = starts.len() - 1;
    let handover = Handover { boundary: Mutex::new(Boundary::Open(first)), window: OnceLock::new() };
    let unknown = OnceLock::new();
    let (head_out, handover_ref) = (&mut *out, &handover);
    let head = move || {
        let head_out = head_out; // moved in: a closure called once
        inflate_head(data, head_out, handover_ref)
    };
    let later = || {
        starts
            .into_par_iter()
            .enumerate()
            .map(|(j, found)| match j {
                0 => inflate_second(data, found, ends[0], last == 0, size, &handover),
                _ => inflate_part(data, found, ends[j], j == last, size, &unknown),
            })
            .collect::<Option<Vec<_>>>()
    };
    let (head, later) = match schedule {
        Schedule::Parallel => rayon::join(head, later),
        #[cfg(test)]
        Schedule::HeadFirst => {
            let head = head();
            (head, later())
        }
        #[cfg(test)]
        Schedule::SecondPartFirst => {
            let later = later();
            (head(), later)
        }
    };
    let mut written = head?;
    let mut checksum = crc_in_parallel(&out[..written]);
    for part in later? {
        written = part.join_into(out, written, &mut checksum)?;
    }
    let second_part_moved = matches!(*handover.boundary.lock().ok()?, Boundary::Moved { .. });
    (written == size && checksum.finalize() == crc).then_some(Joined { written, second_part_moved })
}

/// Offset of the deflate data in a gzip member (RFC 1952 header); None if the header is not one
/// we can skip.
fn deflate_start(raw: &[u8]) -> Option<usize> {
    const FHCRC: u8 = 2;
    const FEXTRA: u8 = 4;
    const FNAME: u8 = 8;
    const FCOMMENT: u8 = 16;
    let header = raw.get(..10)?;
    let flags = header[3];
    if header[..3] != [0x1f, 0x8b, 8] || flags & 0xE0 != 0 {
        return None;
    }
    let mut at = 10;
    if flags & FEXTRA != 0 {
        let length = raw.get(at..at + 2)?;
        at += 2 + usize::from(u16::from_le_bytes([length[0], length[1]]));
    }
    for flag in [FNAME, FCOMMENT] {
        if flags & flag != 0 {
            at += raw.get(at..)?.iter().position(|&b| b == 0)? + 1;
        }
    }
    if flags & FHCRC != 0 {
        at += 2;
    }
    (at < raw.len()).then_some(at)
}

/// Where the first part (the head) stops and the second part starts, and the head's last
/// WINDOW bytes once it has them.
struct Handover {
    boundary: Mutex<Boundary>,
    window: OnceLock<Vec<u8>>,
}

#[derive(Clone, Copy)]
enum Boundary {
    /// the second part's first choice; it may still move later
    Open(usize),
    /// the second part moved from one block start to a later one: the head inflates between
    Moved { from: usize, to: usize },
    /// the head is done at this block start
    Closed(usize),
}

impl Handover {
    /// Where the second part starts, as first chosen.
    fn first_start(&self) -> Option<usize> {
        match *self.boundary.lock().ok()? {
            Boundary::Open(at) | Boundary::Closed(at) | Boundary::Moved { from: at, .. } => Some(at),
        }
    }

    /// The second part asks to start at `to` instead; Some(to) unless the head is done already.
    fn move_to(&self, to: usize) -> Option<usize> {
        let mut boundary = self.boundary.lock().ok()?;
        let Boundary::Open(from) = *boundary else { return None };
        *boundary = Boundary::Moved { from, to };
        Some(to)
    }

    /// The head is done with its first stretch: the gap it must go on to inflate, if any.
    fn close(&self) -> Option<Option<(usize, usize)>> {
        let mut boundary = self.boundary.lock().ok()?;
        match *boundary {
            Boundary::Open(at) => {
                *boundary = Boundary::Closed(at);
                Some(None)
            }
            Boundary::Moved { from, to } => Some(Some((from, to))),
            Boundary::Closed(_) => None,
        }
    }
}

/// The first part: the stream from its start up to the second part's start, straight into
/// `out`; its length. Its last WINDOW bytes go to the handover when known.
fn inflate_head(data: &[u8], out: &mut [u8], handover: &Handover) -> Option<usize> {
    let end = handover.first_start()?;
    let copied = (end / 8 + 1).min(data.len());
    let mut input = Vec::with_capacity(copied + 2);
    input.extend_from_slice(&data[..copied]);
    input.extend([0, 0]);
    let used = deflate::end_stream_at(&mut input, end);
    let mut written = Decompressor::new().deflate_decompress(&input[..used], out).ok()?;
    if let Some((from, to)) = handover.close()? {
        written = inflate_gap(data, from, to, out, written)?;
    }
    if let Some(tail) = written.checked_sub(WINDOW) {
        // ignore failure: the cell is only ever set here
        let _ = handover.window.set(out[tail..written].to_vec());
    }
    Some(written)
}

/// The head goes on from block start `from` to bit `to`, after the `written` bytes in `out`;
/// the new length.
fn inflate_gap(data: &[u8], from: usize, to: usize, out: &mut [u8], written: usize) -> Option<usize> {
    let window = out.get(written.checked_sub(WINDOW)?..written)?;
    let (input, skip) = replay_input(data, window, from, Some(to));
    // The replayed window lands on itself; the padding before it would overwrite bytes of the
    // head: keep them.
    let begin = written.checked_sub(skip)?;
    let kept = out[begin..written - WINDOW].to_vec();
    let inflated = Decompressor::new().deflate_decompress(&input, &mut out[begin..]).ok()?;
    out[begin..written - WINDOW].copy_from_slice(&kept);
    Some(begin + inflated)
}

/// A later part, inflated on its own.
struct Part {
    /// what the marker decoder produced: bytes and window markers
    speculative: deflate::Partial,
    /// what libdeflate produced after it, with `skip` bytes of replayed window in front
    rest: Option<FreshBytes>,
    /// where in `rest` the part's bytes are (the `skip` bytes of replayed window come first)
    rest_range: Range<usize>,
    /// of those bytes
    rest_checksum: crc32fast::Hasher,
}

/// Values the second part decodes at its first choice of start before concluding that window
/// markers live long there.
const PROBE_VALUES: usize = 96 << 10;
/// How far into its share the second part then moves its start, in tenths: the marker decoder
/// runs at about 0.7 of libdeflate's speed, and the head gets the gap on top of its share
/// (measured best on 100k and 1M SPZ files with rounded SH: 3).
const MOVE_TENTHS: usize = 3;

/// The second part. Where window markers outlive a short probe (streams of few distinct bytes
/// copy them along for megabytes) the marker decoder, slower than libdeflate, would trail the
/// head: the part then moves its start further into its share and leaves the gap to the head,
/// which has the real window and inflates it with libdeflate.
fn inflate_second(data: &[u8], found: deflate::Found, end: usize, last: bool, capacity: usize, handover: &Handover) -> Option<Part> {
    let start = found.start;
    let stop = if last { usize::MAX } else { end };
    let probe = Limit { values: capacity, give_up_after: Some(PROBE_VALUES) };
    if let Some(partial) = deflate::decode_from(data, found, stop, probe, &handover.window) {
        return inflate_rest(data, partial, end, last, capacity);
    }
    let found = match deflate::find_block(data, start + (end - start) * MOVE_TENTHS / 10, end) {
        Some(later) if handover.move_to(later.start).is_some() => later,
        _ => deflate::Found::at(start),
    };
    let partial = deflate::decode_from(data, found, stop, Limit::values(capacity), &handover.window)?;
    inflate_rest(data, partial, end, last, capacity)
}

/// The part of the stream from block start `found` to bit `end` (the next part's start, or the
/// end of the data for the `last` part); it inflates to at most `capacity` bytes (the member's
/// length). `preceding` receives the bytes before the start once another thread has them.
fn inflate_part(data: &[u8], found: deflate::Found, end: usize, last: bool, capacity: usize, preceding: &OnceLock<Vec<u8>>) -> Option<Part> {
    let partial = deflate::decode_from(data, found, if last { usize::MAX } else { end }, Limit::values(capacity), preceding)?;
    inflate_rest(data, partial, end, last, capacity)
}

/// After the marker decoder stopped: libdeflate to `end`, behind the window it handed on.
fn inflate_rest(data: &[u8], partial: deflate::Partial, end: usize, last: bool, capacity: usize) -> Option<Part> {
    if partial.finished {
        let rest_checksum = crc32fast::Hasher::new();
        return Some(Part { speculative: partial, rest: None, rest_range: 0..0, rest_checksum });
    }
    let (input, skip) = replay_input(data, &partial.window, partial.stop, (!last).then_some(end));
    // only the pages written are ever backed by memory
    let mut rest = FreshBytes::new(skip + capacity)?;
    let written = Decompressor::new().deflate_decompress(&input, &mut rest).ok()?;
    let rest_range = skip..written.max(skip);
    let rest_checksum = crc_of(&rest[rest_range.clone()]);
    Some(Part { speculative: partial, rest: Some(rest), rest_range, rest_checksum })
}

/// Input for libdeflate to inflate the stream from block start `from` to bit `to` (None: to
/// the end) after the WINDOW bytes `window`: a made-up block that replays them, the stream's
/// bits, and a made-up final block at `to`. Also how many bytes the replay decodes to (they come
/// first in the output).
fn replay_input(data: &[u8], window: &[u8], from: usize, to: Option<usize>) -> (Vec<u8>, usize) {
    let phase = from % 8;
    let (prefix, prefix_bits, skip) = window_block(window, phase);
    // With the prefix as long as `from` modulo 8, the stream's bytes from `from` on keep their
    // bit positions: copy them, the first one sharing its low `phase` bits with the prefix.
    let whole = prefix_bits / 8;
    let first = from / 8;
    let tail = to.map_or(data.len(), |to| (to / 8 + 1).min(data.len()));
    let mut used = whole + tail - first;
    let mut input = Vec::with_capacity(used + 2);
    input.extend_from_slice(&prefix[..whole]);
    input.extend_from_slice(&data[first..tail]);
    input.extend([0, 0]);
    if phase != 0 {
        let low = (1u8 << phase) - 1;
        input[whole] = (input[whole] & !low) | (prefix[whole] & low);
    }
    if let Some(to) = to {
        used = deflate::end_stream_at(&mut input, prefix_bits + (to - from));
    }
    input.truncate(used);
    (input, skip)
}

/// CRC-32 state of `bytes`, to combine with those of the bytes around them.
fn crc_of(bytes: &[u8]) -> crc32fast::Hasher {
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(bytes);
    hasher
}

/// The same, a chunk per task.
fn crc_in_parallel(bytes: &[u8]) -> crc32fast::Hasher {
    let chunks: Vec<crc32fast::Hasher> = bytes.par_chunks(JOIN_CHUNK).map(crc_of).collect();
    chunks.iter().fold(crc32fast::Hasher::new(), |mut whole, chunk| {
        whole.combine(chunk);
        whole
    })
}

/// Bytes per task when joining parts.
const JOIN_CHUNK: usize = 1 << 16;

/// A non-final fixed-Huffman block whose output ends with `window`, padded in front with
/// throw-away bytes so that its length in bits is `phase` modulo 8. Returns its bytes (the last
/// one partly filled when `phase` is not 0), its length in bits and what it decodes to in bytes.
fn window_block(window: &[u8], phase: usize) -> (Vec<u8>, usize, usize) {
    let body: usize = 3 + 7 + window.iter().map(|&b| BitWriter::fixed_literal_bits(b)).sum::<usize>();
    let padding = (phase + 8 - body % 8) % 8; // each 0xFF literal takes 9 bits: one more mod 8
    let mut writer = BitWriter::with_capacity(body.div_ceil(8) + 8);
    writer.put(0, 1); // not final
    writer.put(1, 2); // fixed Huffman codes
    for _ in 0..padding {
        writer.put_fixed_literal(0xFF);
    }
    window.iter().for_each(|&b| writer.put_fixed_literal(b));
    writer.put_fixed_end();
    (writer.bytes, writer.bits, padding + window.len())
}

impl Part {
    /// Write this part into `out` at `at`, its markers filled in from the bytes before `at`, and
    /// add it to `checksum`; the new end, or None if it does not fit or a marker points before
    /// the stream.
    fn join_into(self, out: &mut [u8], at: usize, checksum: &mut crc32fast::Hasher) -> Option<usize> {
        let rest = self.rest.as_ref().map_or(&[][..], |rest| &rest[self.rest_range.clone()]);
        let speculative = self.speculative.output();
        let middle = at + speculative.len();
        let end = middle + rest.len();
        if end > out.len() {
            return None;
        }
        // What each value stands for: itself below 256, else a byte of the window before the part.
        // (One load per value: markers are too scattered for a branch.)
        let window = out.get(at.checked_sub(WINDOW)?..at)?;
        let mut meaning = Box::new([0u8; 1 << 16]);
        meaning.iter_mut().zip((0..=255u8).chain(window.iter().copied())).for_each(|(slot, byte)| *slot = byte);
        let checksums: Vec<crc32fast::Hasher> = out[at..middle]
            .par_chunks_mut(JOIN_CHUNK)
            .zip(speculative.par_chunks(JOIN_CHUNK))
            .map(|(bytes, values)| {
                bytes.iter_mut().zip(values).for_each(|(byte, &value)| *byte = meaning[usize::from(value)]);
                crc_of(bytes)
            })
            .collect();
        checksums.iter().for_each(|chunk| checksum.combine(chunk));
        checksum.combine(&self.rest_checksum);
        out[middle..end].copy_from_slice(rest);
        Some(end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // `printf 'hello hello hello' | gzip -n`: 17 bytes of text
    const HELLO: [u8; 28] = [
        0x1f, 0x8b, 0x08, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x03, 0xcb, 0x48, 0xcd, 0xc9, 0xc9, 0x57, 0xc8, 0x40, 0x90,
        0x00, 0x80, 0x88, 0xf9, 0xe5, 0x11, 0x00, 0x00, 0x00,
    ];

    #[test]
    fn inflates_and_stops_at_the_buffer() {
        let mut out = [0u8; 32];
        assert_eq!(gunzip_into(&HELLO, &mut out), Ok(17));
        assert_eq!(&out[..17], b"hello hello hello");
        assert_eq!(gunzip_into(&HELLO, &mut out[..10]), Err(GunzipError::TooLong(10)));
        assert_eq!(gunzip_into(&HELLO[..20], &mut out), Err(GunzipError::Corrupt));
        let mut bad_crc = HELLO;
        bad_crc[21] ^= 1;
        assert_eq!(gunzip_into(&bad_crc, &mut out), Err(GunzipError::Corrupt));
    }

    fn gzip(data: &[u8], level: i32) -> Vec<u8> {
        let mut compressor = libdeflater::Compressor::new(libdeflater::CompressionLvl::new(level).unwrap_or_default());
        let mut out = vec![0; compressor.gzip_compress_bound(data.len())];
        let n = compressor.gzip_compress(data, &mut out).unwrap_or_else(|e| unreachable!("{e}"));
        out.truncate(n);
        out
    }

    /// SPZ-like bytes: noise, then small values around 128 as quantised SH are, with runs.
    fn sample(n: usize, seed: u64) -> Vec<u8> {
        let mut state = seed;
        (0..n)
            .map(|i| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let r = (state >> 33) as u32;
                if i < n / 5 { r as u8 } else if r.is_multiple_of(7) { 128 } else { 128u8.wrapping_add((r % 23) as u8).wrapping_sub(11) & 0xF8 }
            })
            .collect()
    }

    #[test]
    fn parts_join_into_the_same_bytes() {
        for (n, level, parts) in [(6_000_000, 6, 2), (9_000_000, 1, 3), (5_000_000, 12, 4)] {
            let data = sample(n, n as u64);
            let raw = gzip(&data, level);
            let mut out = vec![0; n];
            assert_eq!(gunzip_in_parts(&raw, &mut out, parts, Schedule::Parallel).map(|j| j.written), Some(n), "n {n} level {level} parts {parts}");
            assert!(out == data);
        }
    }

    #[test]
    fn stored_streams_split_and_odd_members_fall_back() {
        let data = sample(3_000_000, 5);
        let stored = gzip(&data, 0); // stored blocks only
        let mut out = vec![0; data.len()];
        assert_eq!(gunzip_in_parts(&stored, &mut out, 2, Schedule::Parallel).map(|j| j.written), Some(data.len()));
        assert!(out == data);
        // bytes after the member: the trailer is not where splitting looks, so it does not split
        let mut trailing = gzip(&data, 6);
        trailing.extend_from_slice(b"bytes after the member");
        out.fill(0);
        assert_eq!(gunzip_in_parts(&trailing, &mut out, 2, Schedule::Parallel), None);
        assert_eq!(gunzip_into(&trailing, &mut out), Ok(data.len()));
        assert!(out == data);
    }

    #[test]
    fn damage_gets_the_sequential_verdict() {
        // Splitting may fail on damaged data, but it must never succeed where one piece fails,
        // nor give other bytes.
        let data = sample(4_000_000, 9);
        let mut expected = vec![0; data.len()];
        let mut out = vec![0; data.len()];
        let mut state = 3u64;
        for level in [6, 0] {
            let raw = gzip(&data, level);
            for round in 0..30 {
                let mut bad = raw.clone();
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
                let at = 10 + (state >> 20) as usize % (bad.len() - 10);
                match round % 3 {
                    0 => bad[at] ^= 1 << (state % 8),
                    1 => bad.truncate(at),
                    _ => bad[at..(at + 64).min(raw.len())].fill((state >> 8) as u8),
                }
                let sequential = Decompressor::new().gzip_decompress(&bad, &mut expected).ok();
                for parts in [2, 3] {
                    if let Some(n) = gunzip_in_parts(&bad, &mut out, parts, Schedule::Parallel).map(|j| j.written) {
                        assert_eq!(Some(n), sequential, "level {level} round {round} parts {parts}");
                        assert!(out[..n] == expected[..n]);
                    }
                }
                assert_eq!(gunzip_into(&bad, &mut out).ok(), sequential);
            }
            out.truncate(1000); // too small: the bomb guard holds in parts too
            assert_eq!(gunzip_into(&raw, &mut out), Err(GunzipError::TooLong(1000)));
            out.resize(data.len(), 0);
        }
    }

    /// SPZ-like bytes: noise (positions and the like), then small SH values around 128 rounded
    /// to `step` (the reference writer keeps 4-5 bits: a step of 16 or 8).
    fn spz_like(n: usize, step: u8, seed: u64) -> Vec<u8> {
        let mut state = seed;
        (0..n)
            .map(|i| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let r = (state >> 33) as u32;
                // bell-shaped around 128, standard deviation about 38 (SH of about 0.3)
                let value = r % 66 + (r >> 7) % 66 + (r >> 14) % 66 + (r >> 21) % 66;
                if i < n / 10 { r as u8 } else { value as u8 / step * step }
            })
            .collect()
    }

    #[test]
    fn where_markers_live_long_the_second_part_moves_and_the_head_fills_the_gap() {
        for (step, lives_long) in [(16, true), (1, false)] {
            let data = spz_like(6_000_000, step, 7);
            let raw = gzip(&data, 6);
            // the probe gives up, or not, at the second part's first choice of start
            let stream = &raw[10..raw.len() - 8];
            let found = deflate::find_block(stream, 4 * stream.len(), 8 * stream.len());
            let probe = Limit { values: data.len(), give_up_after: Some(PROBE_VALUES) };
            let probed = found.and_then(|found| deflate::decode_from(stream, found, usize::MAX, probe, &OnceLock::new()));
            assert_eq!(probed.is_none(), lives_long, "step {step}");
            // whoever is first, the bytes are the same; the second part moves only when first
            for (schedule, moves) in [(Schedule::SecondPartFirst, lives_long), (Schedule::HeadFirst, false), (Schedule::Parallel, false)] {
                let mut out = vec![0; data.len()];
                let joined = gunzip_in_parts(&raw, &mut out, 2, schedule).unwrap_or_else(|| unreachable!("step {step}"));
                assert_eq!(joined.written, data.len());
                if !matches!(schedule, Schedule::Parallel) {
                    assert_eq!(joined.second_part_moved, moves, "step {step}");
                }
                assert!(out == data, "step {step}");
            }
            // with more parts, the second one's share ends where the third one starts
            for schedule in [Schedule::SecondPartFirst, Schedule::HeadFirst, Schedule::Parallel] {
                let mut out = vec![0; data.len()];
                let joined = gunzip_in_parts(&raw, &mut out, 3, schedule).unwrap_or_else(|| unreachable!("step {step}"));
                assert_eq!(joined.written, data.len());
                assert!(out == data, "step {step}, 3 parts");
            }
        }
    }
}
