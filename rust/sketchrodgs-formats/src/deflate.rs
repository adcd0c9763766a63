//! Just enough of a DEFLATE decoder (RFC 1951) to start inflating in the middle of a stream,
//! where the 32 KiB of output that back-references may reach into is not known yet.
//!
//! Such output is kept as u16: a byte below 256, or a marker `256 + w` for byte `w` of the
//! unknown window (the 32 KiB before the start). Once the last 32 KiB decoded hold no marker, the
//! rest of the stream needs nothing from before the start, and libdeflate can take over (see
//! `gzip`). This decoder only has to be correct and bounded, not fast: it runs over a small part
//! of a stream, and over candidate block starts while looking for one.

use std::sync::OnceLock;

/// How far back a DEFLATE back-reference may reach.
pub(crate) const WINDOW: usize = 32 * 1024;

/// Bits of a byte slice, least significant bit of each byte first, read through a 64-bit buffer.
struct Bits<'a> {
    data: &'a [u8],
    /// next byte to load into `buffer`
    next: usize,
    buffer: u64,
    /// valid bits in `buffer`
    count: u32,
}

impl<'a> Bits<'a> {
    fn at(data: &'a [u8], pos: usize) -> Self {
        let mut bits = Bits { data, next: pos / 8, buffer: 0, count: 0 };
        bits.refill();
        bits.buffer >>= pos % 8;
        bits.count -= (pos % 8) as u32;
        bits
    }

    /// Bit position of the next bit.
    fn pos(&self) -> usize {
        8 * self.next - self.count as usize
    }

    /// Fill the buffer to at least 56 bits; bytes past the end read as 0.
    #[inline]
    fn refill(&mut self) {
        if let Some(eight) = self.data.get(self.next..self.next + 8) {
            let word = u64::from_le_bytes([eight[0], eight[1], eight[2], eight[3], eight[4], eight[5], eight[6], eight[7]]);
            self.buffer |= word << self.count;
            let loaded = (63 - self.count) / 8;
            self.next += loaded as usize;
            self.count += 8 * loaded;
        } else {
            while self.count <= 56 {
                self.buffer |= u64::from(self.data.get(self.next).copied().unwrap_or(0)) << self.count;
                self.next += 1;
                self.count += 8;
            }
        }
    }

    /// The next `n` (at most 32) bits without consuming them.
    #[inline]
    fn peek(&mut self, n: u32) -> u32 {
        if self.count < n {
            self.refill();
        }
        (self.buffer & ((1u64 << n) - 1)) as u32
    }

    /// Consume `n` (at most 32) bits; None past the end of the data.
    #[inline]
    fn take(&mut self, n: u32) -> Option<u32> {
        let value = self.peek(n);
        self.buffer >>= n;
        self.count -= n;
        (self.pos() <= 8 * self.data.len()).then_some(value)
    }

    /// Skip `n` bits, any number; None past the end of the data.
    fn skip(&mut self, n: usize) -> Option<()> {
        let pos = self.pos() + n;
        if pos > 8 * self.data.len() {
            return None;
        }
        *self = Bits::at(self.data, pos);
        Some(())
    }
}

/// How many codes of each length `lengths` asks for, and whether they fill the code space; None
/// when they over-subscribe it.
fn kraft(lengths: &[u8]) -> Option<([u32; 16], bool)> {
    let mut count = [0u32; 16];
    for &length in lengths {
        *count.get_mut(usize::from(length))? += 1;
    }
    count[0] = 0;
    let mut left: i64 = 1;
    for &c in &count[1..] {
        left = 2 * left - i64::from(c);
        if left < 0 {
            return None;
        }
    }
    Some((count, left == 0))
}

/// A canonical Huffman code as a lookup table on the next `max` bits.
struct Huffman {
    /// symbol << 4 | code length, 0 where no code starts with those bits
    table: Vec<u16>,
    max: u32,
}

impl Huffman {
    /// The code for `lengths` (0: symbol unused), and whether it is complete. None when the
    /// lengths over-subscribe the code space.
    fn new(lengths: &[u8]) -> Option<(Huffman, bool)> {
        let (count, complete) = kraft(lengths)?;
        let max = (1..16).rev().find(|&l| count[l] > 0).unwrap_or(1) as u32;
        let mut next = [0u32; 16];
        let mut code = 0;
        for bits in 1..16 {
            code = (code + count[bits - 1]) << 1;
            next[bits] = code;
        }
        let mut table = vec![0u16; 1 << max];
        for (symbol, &length) in lengths.iter().enumerate() {
            if length == 0 {
                continue;
            }
            let length = u32::from(length);
            let code = next[length as usize];
            next[length as usize] += 1;
            let reversed = code.reverse_bits() >> (32 - length);
            let entry = ((symbol as u16) << 4) | length as u16;
            for slot in (reversed as usize..table.len()).step_by(1 << length) {
                table[slot] = entry;
            }
        }
        Some((Huffman { table, max }, complete))
    }

    #[inline(always)]
    fn decode(&self, bits: &mut Bits<'_>) -> Option<u16> {
        let entry = self.table[bits.peek(self.max) as usize];
        let length = entry & 15;
        if length == 0 {
            return None;
        }
        bits.take(u32::from(length))?;
        Some(entry >> 4)
    }
}

/// The codes of one block, after its header.
enum Block {
    Stored(usize),
    Coded { literals: Huffman, distances: Huffman },
}

const LENGTH_BASE: [u16; 29] = [3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258];
const LENGTH_EXTRA: [u8; 29] = [0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0];
const DISTANCE_BASE: [u16; 30] = [
    1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577,
];
const DISTANCE_EXTRA: [u8; 30] = [0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13];
/// Order in which a dynamic header lists the code lengths of the code-length alphabet.
const CODE_LENGTH_ORDER: [usize; 19] = [16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15];

/// A literal/length or distance code as zlib accepts it: complete, or a single code of one bit
/// (and, for distances, no code at all).
fn usable(code: Option<(Huffman, bool)>, may_be_empty: bool) -> Option<Huffman> {
    let (code, complete) = code?;
    let single = code.max == 1 && code.table.iter().filter(|&&e| e != 0).count() == 1;
    let empty = code.table.iter().all(|&e| e == 0);
    (complete || single || (may_be_empty && empty)).then_some(code)
}

/// Read a block header; (is the final block, its codes).
fn read_header(bits: &mut Bits<'_>) -> Option<(bool, Block)> {
    let last = bits.take(1)? == 1;
    match bits.take(2)? {
        0 => {
            bits.skip((8 - bits.pos() % 8) % 8)?;
            let (length, inverse) = (bits.take(16)?, bits.take(16)?);
            (length == !inverse & 0xFFFF).then_some((last, Block::Stored(length as usize)))
        }
        1 => {
            let mut lengths = [8u8; 288];
            lengths[144..256].fill(9);
            lengths[256..280].fill(7);
            let literals = Huffman::new(&lengths)?.0;
            let distances = Huffman::new(&[5u8; 30])?.0;
            Some((last, Block::Coded { literals, distances }))
        }
        2 => {
            let literal_count = bits.take(5)? as usize + 257;
            let distance_count = bits.take(5)? as usize + 1;
            let code_length_count = bits.take(4)? as usize + 4;
            if literal_count > 286 || distance_count > 30 {
                return None;
            }
            let mut code_lengths = [0u8; 19];
            for &symbol in &CODE_LENGTH_ORDER[..code_length_count] {
                code_lengths[symbol] = bits.take(3)? as u8;
            }
            if !kraft(&code_lengths)?.1 {
                return None; // checked before building a table: most candidate starts fail here
            }
            let code_length_code = Huffman::new(&code_lengths)?.0;
            let mut lengths = [0u8; 286 + 30];
            let total = literal_count + distance_count;
            let mut i = 0;
            while i < total {
                let (value, repeat) = match code_length_code.decode(bits)? {
                    symbol @ 0..=15 => (symbol as u8, 1),
                    16 => (*lengths[..i].last()?, 3 + bits.take(2)? as usize),
                    17 => (0, 3 + bits.take(3)? as usize),
                    _ => (0, 11 + bits.take(7)? as usize),
                };
                lengths.get_mut(i..i + repeat)?.fill(value);
                i += repeat;
            }
            if i != total || lengths[256] == 0 {
                return None;
            }
            let literals = usable(Huffman::new(&lengths[..literal_count]), false)?;
            let distances = usable(Huffman::new(&lengths[literal_count..total]), true)?;
            Some((last, Block::Coded { literals, distances }))
        }
        _ => None,
    }
}

/// Output being decoded from the middle of a stream.
struct Speculative {
    output: Vec<u16>,
    /// index just past the last marker written
    clean_from: usize,
    /// most values to decode (a block can expand without bound)
    limit: usize,
}

impl Speculative {
    /// Append `length` values from `distance` back (the caller checked that `distance` reaches
    /// no further than the window).
    fn copy(&mut self, distance: usize, length: usize) {
        let here = self.output.len();
        // from the unknown window: markers
        let unknown = distance.saturating_sub(here).min(length);
        self.output.extend((0..unknown).map(|k| (256 + WINDOW + here + k - distance) as u16));
        if unknown > 0 {
            self.clean_from = here + unknown;
        }
        let copied = length - unknown;
        if copied == 0 {
            return;
        }
        let from = here + unknown - distance; // the copy starts inside the output
        // Where source and destination overlap, the output repeats with the period `distance`:
        // copy what is there, which doubles what is there, until done.
        let mut remaining = copied;
        while remaining > 0 {
            let chunk = (self.output.len() - from).min(remaining);
            self.output.extend_from_within(from..from + chunk);
            remaining -= chunk;
        }
        // markers copied along keep the window unclean
        if self.clean_from > from
            && let Some(last) = self.output[here + unknown..].iter().rposition(|&v| v >= 256)
        {
            self.clean_from = here + unknown + last + 1;
        }
    }

    /// Put in the bytes of the window, now known: `window` holds the WINDOW bytes before the start.
    fn resolve(&mut self, window: &[u8]) {
        for value in self.output.iter_mut().filter(|v| **v >= 256) {
            *value = u16::from(window[usize::from(*value - 256)]);
        }
        self.clean_from = 0;
    }

    /// Decode the body of one block; None on anything a valid stream cannot hold.
    fn block(&mut self, bits: &mut Bits<'_>, block: &Block) -> Option<()> {
        let (literals, distances) = match block {
            Block::Stored(length) => {
                let start = bits.pos() / 8;
                let bytes = bits.data.get(start..start + length)?;
                bytes.iter().for_each(|&b| self.output.push(u16::from(b)));
                return bits.skip(8 * length);
            }
            Block::Coded { literals, distances } => (literals, distances),
        };
        loop {
            if self.output.len() > self.limit {
                return None;
            }
            let symbol = literals.decode(bits)?;
            match symbol {
                0..=255 => self.output.push(symbol),
                256 => return Some(()),
                _ => {
                    let index = usize::from(symbol).checked_sub(257).filter(|&i| i < 29)?;
                    let length = usize::from(LENGTH_BASE[index]) + bits.take(u32::from(LENGTH_EXTRA[index]))? as usize;
                    let code = usize::from(distances.decode(bits)?);
                    let (base, extra) = (*DISTANCE_BASE.get(code)?, DISTANCE_EXTRA[code]);
                    let distance = usize::from(base) + bits.take(u32::from(extra))? as usize;
                    let here = self.output.len();
                    if distance > here + WINDOW {
                        return None;
                    }
                    self.copy(distance, length);
                }
            }
        }
    }

    /// The last WINDOW values hold no marker.
    fn clean(&self) -> bool {
        self.output.len() >= WINDOW && self.output.len() - self.clean_from >= WINDOW
    }
}

/// Where decoding from the middle stopped.
pub(crate) struct Partial {
    /// Bytes (< 256) and window markers (`256 + w`) decoded from the start.
    pub output: Vec<u16>,
    /// Bit position of the block boundary where decoding stopped.
    pub stop: usize,
    /// Decoding reached `end` or the final block: nothing is left for libdeflate.
    pub finished: bool,
    /// Otherwise the WINDOW bytes before `stop`, for the inflater that goes on from there.
    pub window: Vec<u8>,
}

/// Decode from the block starting at bit `start` of `data` until the last WINDOW bytes hold no
/// marker (at a block boundary), or until bit `end` (a block boundary), or past the final block.
/// Once `preceding` holds the WINDOW bytes before `start` (another thread decodes them), the
/// markers are filled in from it and decoding stops at the next block boundary. None when the
/// data is not a valid stream from `start`, when decoding passes `end` without stopping on it,
/// or when more than `limit` bytes would be needed.
pub(crate) fn decode_from(data: &[u8], start: usize, end: usize, limit: usize, preceding: &OnceLock<Vec<u8>>) -> Option<Partial> {
    let mut bits = Bits::at(data, start);
    let mut decoded = Speculative { output: Vec::with_capacity(4 * WINDOW), clean_from: 0, limit };
    loop {
        let (last, block) = read_header(&mut bits)?;
        decoded.block(&mut bits, &block)?;
        let known = preceding.get().filter(|window| window.len() == WINDOW);
        if let Some(window) = known {
            decoded.resolve(window);
        }
        let finished = last || bits.pos() == end;
        if finished || known.is_some() || decoded.clean() {
            let output = decoded.output;
            let window = if finished {
                Vec::new()
            } else {
                // the last WINDOW bytes before `stop`: of the output, and before it of `preceding`
                let own = &output[output.len().saturating_sub(WINDOW)..];
                let before = known.map_or(&[][..], |window| &window[own.len()..]);
                before.iter().copied().chain(own.iter().map(|&v| v as u8)).collect()
            };
            return Some(Partial { output, stop: bits.pos(), finished, window });
        }
        if bits.pos() > end {
            return None;
        }
    }
}

/// Most bytes a block may decode to while looking for a block start (zlib and libdeflate end
/// blocks far sooner).
const BLOCK_LIMIT: usize = 4 << 20;
/// How far to look for a block start; encoders end blocks far sooner (but for stored data).
const SEARCH_BYTES: usize = 1 << 20;
/// Work allowed while looking for one block start, in decoded bytes (about 0.1 s).
const SEARCH_BUDGET: usize = 16 << 20;
/// What building a candidate's Huffman tables counts for against that budget.
const TABLE_COST: usize = 1 << 15;

/// The first block start found in `from..to`: of a block with its own Huffman codes whose header
/// is valid and whose body decodes, followed by a valid block header; or of the block after a
/// stored block whose body follows (a stored header is only 35 bits and a 16-bit check) by a
/// block that decodes. A stored block's own start is ambiguous (its header may sit anywhere in
/// the zero bits before its byte boundary), so the block after it is taken.
pub(crate) fn find_block(data: &[u8], from: usize, to: usize) -> Option<usize> {
    let to = to.min(8 * data.len()).min(from + 8 * SEARCH_BYTES);
    // Crafted data could make many starts look valid for long: bound the work over all of them
    // (a candidate past its header costs its tables and the bytes it decodes).
    let mut budget = SEARCH_BUDGET;
    for start in from..to {
        let mut bits = Bits::at(data, start);
        // cheap test first: not final, stored (000) or dynamic (100)
        let kind = bits.peek(3);
        if kind != 0b100 && kind != 0b000 {
            continue;
        }
        let Some((false, block)) = read_header(&mut bits) else { continue };
        let mut decoded = Speculative { output: Vec::new(), clean_from: 0, limit: BLOCK_LIMIT.min(budget) };
        let found = decoded.block(&mut bits, &block).and_then(|()| {
            let after = bits.pos();
            let (_, next) = read_header(&mut bits)?;
            if kind == 0b100 {
                return Some(start);
            }
            decoded.block(&mut bits, &next)?;
            Some(after)
        });
        if found.is_some() {
            return found;
        }
        budget = budget.checked_sub(TABLE_COST + decoded.output.len())?;
    }
    None
}

/// Bits written least significant first, as DEFLATE stores them.
pub(crate) struct BitWriter {
    pub bytes: Vec<u8>,
    pub bits: usize,
}

impl BitWriter {
    pub fn new() -> Self {
        BitWriter { bytes: Vec::new(), bits: 0 }
    }

    /// The low `n` (at most 24) bits of `value`.
    pub fn put(&mut self, value: u32, n: u32) {
        let shift = self.bits % 8;
        let mut pending = u32::from(if shift == 0 { 0 } else { self.bytes.pop().unwrap_or(0) });
        pending |= (value & ((1 << n) - 1)) << shift;
        self.bits += n as usize;
        for _ in 0..(shift + n as usize).div_ceil(8) {
            self.bytes.push(pending as u8);
            pending >>= 8;
        }
    }

    /// A Huffman code: stored from its most significant bit.
    fn put_code(&mut self, code: u32, length: u32) {
        self.put(code.reverse_bits() >> (32 - length), length);
    }

    /// A literal of the fixed Huffman code.
    pub fn put_fixed_literal(&mut self, byte: u8) {
        match byte {
            0..=143 => self.put_code(0x30 + u32::from(byte), 8),
            _ => self.put_code(0x190 + u32::from(byte - 144), 9),
        }
    }

    /// End of block in the fixed Huffman code.
    pub fn put_fixed_end(&mut self) {
        self.put_code(0, 7);
    }

    /// Bits a fixed-Huffman literal takes.
    pub fn fixed_literal_bits(byte: u8) -> usize {
        if byte < 144 { 8 } else { 9 }
    }
}

/// Overwrite the stream in `bytes` from bit `at` with an empty final block (fixed Huffman,
/// end of block only), so that an inflater stops there. Returns how many bytes the stream now
/// takes; `bytes` must hold them.
pub(crate) fn end_stream_at(bytes: &mut [u8], at: usize) -> usize {
    let used = (at + 10).div_ceil(8);
    let byte = at / 8;
    bytes[byte] &= (1u8 << (at % 8)) - 1;
    bytes[byte + 1..used].fill(0);
    // BFINAL = 1, BTYPE = 01 (fixed), then the 7 zero bits of end-of-block
    for bit in [at, at + 1] {
        bytes[bit / 8] |= 1 << (bit % 8);
    }
    used
}

#[cfg(test)]
mod tests {
    use super::*;

    fn deflate(data: &[u8], level: i32) -> Vec<u8> {
        let level = libdeflater::CompressionLvl::new(level).unwrap_or_default();
        let mut compressor = libdeflater::Compressor::new(level);
        let mut out = vec![0; compressor.deflate_compress_bound(data.len())];
        let n = compressor.deflate_compress(data, &mut out).unwrap_or_else(|e| unreachable!("{e}"));
        out.truncate(n);
        out
    }

    fn sample(n: usize, seed: u64) -> Vec<u8> {
        // text-like: words from a small vocabulary, so there are matches of every distance
        let words: [&[u8]; 8] = [b"rope ", b"cable ", b"chain ", b"stem ", b"splat ", b"gauss ", b"rod ", b"twist "];
        let mut state = seed;
        let mut out = Vec::with_capacity(n + 8);
        while out.len() < n {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            out.extend_from_slice(words[(state >> 61) as usize]);
            out.push((state >> 40) as u8);
        }
        out.truncate(n);
        out
    }

    #[test]
    fn from_the_start_it_is_a_plain_inflater() {
        let data = sample(2_000_000, 1);
        let compressed = deflate(&data, 6);
        let partial = decode_from(&compressed, 0, usize::MAX, usize::MAX, &OnceLock::new()).unwrap_or_else(|| unreachable!());
        // stops once 32 KiB are clean; what it has matches the data
        assert!(partial.output.len() >= WINDOW && partial.output.len() < data.len());
        assert!(partial.output.iter().zip(&data).all(|(&a, &b)| a == u16::from(b)));
    }

    #[test]
    fn from_the_middle_markers_name_window_bytes() {
        let data = sample(2_000_000, 2);
        let compressed = deflate(&data, 6);
        let start = find_block(&compressed, 4 * compressed.len(), 8 * compressed.len()).unwrap_or_else(|| unreachable!());
        let partial = decode_from(&compressed, start, usize::MAX, usize::MAX, &OnceLock::new()).unwrap_or_else(|| unreachable!());
        // where the block starts in the data: find it by decoding everything up to `start`
        let mut ending = compressed.clone();
        let used = end_stream_at(&mut ending, start);
        let mut head = vec![0; data.len()];
        let offset = libdeflater::Decompressor::new().deflate_decompress(&ending[..used], &mut head).unwrap_or_else(|e| unreachable!("{e}"));
        assert!(offset > WINDOW && offset < data.len());
        assert!(partial.output.iter().any(|&v| v >= 256), "text this repetitive refers back across the start");
        for (i, &v) in partial.output.iter().enumerate() {
            let expected = data[offset + i];
            let got = if v < 256 { v as u8 } else { data[offset - WINDOW + usize::from(v - 256)] };
            assert_eq!(got, expected, "at {i}");
        }
        // with the bytes before the start known, the markers are filled in after the first block
        let known = OnceLock::from(data[offset - WINDOW..offset].to_vec());
        let resolved = decode_from(&compressed, start, usize::MAX, usize::MAX, &known).unwrap_or_else(|| unreachable!());
        assert!(resolved.output.len() < partial.output.len());
        assert!(resolved.output.iter().zip(&data[offset..]).all(|(&v, &b)| v == u16::from(b)));
        let stop = offset + resolved.output.len();
        assert_eq!(resolved.window, data[stop - WINDOW..stop]);
    }

    #[test]
    fn stored_blocks_are_found_too() {
        let data = sample(400_000, 3);
        let stored = deflate(&data, 0);
        let start = find_block(&stored, 8 * 100_000, 8 * stored.len()).unwrap_or_else(|| unreachable!());
        let partial = decode_from(&stored, start, usize::MAX, usize::MAX, &OnceLock::new()).unwrap_or_else(|| unreachable!());
        // the block after a stored one starts on a byte, and stored blocks need no window
        assert_eq!(start % 8, 0);
        let offset = data.windows(64).position(|w| w.iter().zip(&partial.output).all(|(&a, &b)| u16::from(a) == b));
        assert!(offset.is_some_and(|o| o > 90_000 && o % 65_535 == 0), "{offset:?}");
    }

    #[test]
    fn random_bytes_are_not_taken_for_a_block() {
        let mut state = 7u64;
        let noise: Vec<u8> = (0..200_000)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
                (state >> 56) as u8
            })
            .collect();
        assert_eq!(find_block(&noise, 0, 8 * noise.len()), None);
    }

    #[test]
    fn fixed_literals_round_trip_through_libdeflate() {
        let mut writer = BitWriter::new();
        writer.put(1, 1);
        writer.put(1, 2);
        for b in 0..=255u8 {
            writer.put_fixed_literal(b);
        }
        writer.put_fixed_end();
        let mut out = vec![0; 300];
        let n = libdeflater::Decompressor::new().deflate_decompress(&writer.bytes, &mut out).unwrap_or_else(|e| unreachable!("{e}"));
        assert_eq!(&out[..n], (0..=255u8).collect::<Vec<_>>().as_slice());
        let expected: usize = 3 + 7 + (0..=255u8).map(BitWriter::fixed_literal_bits).sum::<usize>();
        assert_eq!(writer.bits, expected);
    }
}
