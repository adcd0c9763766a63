//! Whole-buffer gzip inflation with libdeflate, split over the cores for big streams.
//!
//! The caller knows how many bytes the stream should hold and passes a buffer of that size, so
//! a stream that expands further (a gzip bomb, or a count that disagrees with the data) stops as
//! soon as the buffer is full.
//!
//! One deflate stream is sequential by nature, and libdeflate inflates it at about 350 MB/s here;
//! a million SPZ splats with SH degree 3 are 65 MB. Big streams are therefore cut into one part
//! per core, in the way of pugz and rapidgzip: each part after the first looks for a block start
//! past its share of the compressed bits, decodes from there with markers for the unknown 32 KiB
//! window (`deflate`) until its last 32 KiB are marker-free (or, for the second part, until the
//! first part is done and its last 32 KiB fill the markers in: in streams of few distinct bytes
//! markers live long), and hands the rest of its share to libdeflate behind a made-up block that
//! replays those 32 KiB as the window. Each share ends in
//! a made-up final block at the next part's start. The parts are then joined, the markers filled
//! in from the bytes before each part, and the member's CRC and length checked. Anything
//! unexpected (no block start found, a CRC mismatch, bytes after the member) falls back to one
//! sequential libdeflate call, whose verdict stands.

use std::sync::OnceLock;

use libdeflater::{DecompressionError, Decompressor};
use rayon::prelude::*;

use crate::deflate::{self, BitWriter, WINDOW};

/// Compressed bytes per part below which a stream is inflated in one piece.
const PART_MIN_BYTES: usize = 1 << 20;
/// Most bytes one part decodes with the slow decoder before giving up on splitting.
const SPECULATIVE_LIMIT: usize = 8 << 20;

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
        && let Some(written) = gunzip_in_parts(raw, out, parts)
    {
        return Ok(written);
    }
    Decompressor::new().gzip_decompress(raw, out).map_err(|error| match error {
        DecompressionError::InsufficientSpace => GunzipError::TooLong(out.len()),
        DecompressionError::BadData => GunzipError::Corrupt,
    })
}

/// Inflate in `parts` pieces in parallel; None where that cannot be done or checked (the caller
/// then inflates in one piece).
fn gunzip_in_parts(raw: &[u8], out: &mut [u8], parts: usize) -> Option<usize> {
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
    let starts: Vec<usize> = (1..parts)
        .into_par_iter()
        .filter_map(|i| deflate::find_block(data, bits * i / parts, bits * (i + 1) / parts))
        .collect();
    if starts.is_empty() {
        return None;
    }
    let ends: Vec<usize> = starts.iter().copied().chain([bits]).collect();
    let last = starts.len() - 1;
    // The first part publishes its last WINDOW bytes, so that the second part can stop guessing.
    let (head_window, unknown) = (OnceLock::new(), OnceLock::new());
    let (head, later) = rayon::join(
        || inflate_head(data, ends[0], out, &head_window),
        || {
            (0..starts.len())
                .into_par_iter()
                .map(|j| inflate_part(data, starts[j], ends[j + 1], j == last, size, if j == 0 { &head_window } else { &unknown }))
                .collect::<Option<Vec<_>>>()
        },
    );
    let (mut written, mut checksum) = head?;
    for part in later? {
        written = part.join_into(out, written, &mut checksum)?;
    }
    (written == size && checksum.finalize() == crc).then_some(written)
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

/// The first part: the stream from its start up to bit `end`, straight into `out`; its length
/// and checksum. Its last WINDOW bytes go to `window` as soon as they are known.
fn inflate_head(data: &[u8], end: usize, out: &mut [u8], window: &OnceLock<Vec<u8>>) -> Option<(usize, crc32fast::Hasher)> {
    let copied = (end / 8 + 1).min(data.len());
    let mut input = big_buffer(copied + 2);
    input[..copied].copy_from_slice(&data[..copied]);
    let used = deflate::end_stream_at(&mut input, end);
    let written = Decompressor::new().deflate_decompress(&input[..used], out).ok()?;
    if let Some(tail) = written.checked_sub(WINDOW) {
        // ignore failure: the cell is only ever set here
        let _ = window.set(out[tail..written].to_vec());
    }
    Some((written, crc_of(&out[..written])))
}

/// A later part, inflated on its own.
struct Part {
    /// what the slow decoder produced: bytes and window markers
    speculative: Vec<u16>,
    /// what libdeflate produced after it, with `skip` bytes of replayed window in front
    rest: Vec<u8>,
    skip: usize,
    /// of `rest` past `skip`
    rest_checksum: crc32fast::Hasher,
}

/// The part of the stream from block start `start` to bit `end` (the next part's start, or the
/// end of the data for the `last` part); it inflates to at most `capacity` bytes (the member's
/// length: only the pages written are ever backed by memory). `preceding`
/// receives the bytes before `start` once another thread has them.
fn inflate_part(data: &[u8], start: usize, end: usize, last: bool, capacity: usize, preceding: &OnceLock<Vec<u8>>) -> Option<Part> {
    let partial = deflate::decode_from(data, start, if last { usize::MAX } else { end }, SPECULATIVE_LIMIT, preceding)?;
    if partial.finished {
        let rest_checksum = crc32fast::Hasher::new();
        return Some(Part { speculative: partial.output, rest: Vec::new(), skip: 0, rest_checksum });
    }
    let phase = partial.stop % 8;
    let (prefix, prefix_bits, skip) = window_block(&partial.window, phase);
    // With the prefix as long as `stop` modulo 8, the stream's bytes from `stop` on keep their
    // bit positions: copy them, the first one sharing its low `phase` bits with the prefix.
    let whole = prefix_bits / 8;
    let first = partial.stop / 8;
    let tail = if last { data.len() } else { (end / 8 + 1).min(data.len()) };
    let mut used = whole + tail - first;
    let mut input = big_buffer(used + 2);
    input[..whole].copy_from_slice(&prefix[..whole]);
    input[whole..used].copy_from_slice(&data[first..tail]);
    if phase != 0 {
        let low = (1u8 << phase) - 1;
        input[whole] = (input[whole] & !low) | (prefix[whole] & low);
    }
    if !last {
        used = deflate::end_stream_at(&mut input, prefix_bits + (end - partial.stop));
    }
    let mut rest = big_buffer(skip + capacity);
    let written = Decompressor::new().deflate_decompress(&input[..used], &mut rest).ok()?;
    rest.truncate(written);
    let rest_checksum = crc_of(rest.get(skip..)?);
    Some(Part { speculative: partial.output, rest, skip, rest_checksum })
}

/// CRC-32 state of `bytes`, to combine with those of the bytes around them.
fn crc_of(bytes: &[u8]) -> crc32fast::Hasher {
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(bytes);
    hasher
}

/// A non-final fixed-Huffman block whose output ends with `window`, padded in front with
/// throw-away bytes so that its length in bits is `phase` modulo 8. Returns its bytes (the last
/// one partly filled when `phase` is not 0), its length in bits and what it decodes to in bytes.
fn window_block(window: &[u8], phase: usize) -> (Vec<u8>, usize, usize) {
    let body: usize = 3 + 7 + window.iter().map(|&b| BitWriter::fixed_literal_bits(b)).sum::<usize>();
    let padding = (phase + 8 - body % 8) % 8; // each 0xFF literal takes 9 bits: one more mod 8
    let mut writer = BitWriter::new();
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
        let rest = self.rest.get(self.skip..).unwrap_or(&[]);
        let middle = at + self.speculative.len();
        let end = middle + rest.len();
        if end > out.len() {
            return None;
        }
        let window_start = at.checked_sub(WINDOW);
        for (i, &value) in self.speculative.iter().enumerate() {
            out[at + i] = match value {
                0..=255 => value as u8,
                marker => out[window_start? + usize::from(marker - 256)],
            };
        }
        checksum.combine(&crc_of(&out[at..middle]));
        checksum.combine(&self.rest_checksum);
        out[middle..end].copy_from_slice(rest);
        Some(end)
    }
}

/// A zeroed buffer whose pages the kernel may back with huge pages (first touches of fresh
/// memory are a large part of the cost here otherwise).
fn big_buffer(len: usize) -> Vec<u8> {
    let buffer = vec![0u8; len];
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let begin = (buffer.as_ptr() as usize).next_multiple_of(HUGE);
        let end = (buffer.as_ptr() as usize + len) / HUGE * HUGE;
        if end > begin {
            // SAFETY: advice on pages of a live allocation we own; it changes no contents.
            unsafe { libc::madvise(begin as *mut libc::c_void, end - begin, libc::MADV_HUGEPAGE) };
        }
    }
    buffer
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
            assert_eq!(gunzip_in_parts(&raw, &mut out, parts), Some(n), "n {n} level {level} parts {parts}");
            assert!(out == data);
        }
    }

    #[test]
    fn stored_streams_split_and_odd_members_fall_back() {
        let data = sample(3_000_000, 5);
        let stored = gzip(&data, 0); // stored blocks only
        let mut out = vec![0; data.len()];
        assert_eq!(gunzip_in_parts(&stored, &mut out, 2), Some(data.len()));
        assert!(out == data);
        // bytes after the member: the trailer is not where splitting looks, so it does not split
        let mut trailing = gzip(&data, 6);
        trailing.extend_from_slice(b"bytes after the member");
        out.fill(0);
        assert_eq!(gunzip_in_parts(&trailing, &mut out, 2), None);
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
                    if let Some(n) = gunzip_in_parts(&bad, &mut out, parts) {
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
}
