//! Just enough of a DEFLATE decoder (RFC 1951) to start inflating in the middle of a stream,
//! where the 32 KiB of output that back-references may reach into is not known yet.
//!
//! Output is kept as u16: a byte below 256, or a marker `256 + w` for byte `w` of the unknown
//! window (the 32 KiB before the start). The buffer begins with those WINDOW markers, so a
//! back-reference into the window is a plain copy that carries markers along. Once the last
//! 32 KiB decoded hold no marker, the rest of the stream needs nothing from before the start,
//! and libdeflate can take over (see `gzip`). In streams of few distinct bytes markers live for
//! megabytes, so this decoder does real work beside libdeflate and is built the same way:
//! one refill of a 64-bit bit buffer per symbol, two-level tables whose entries carry the
//! length or distance base and its extra bits, copies in chunks of 8 values.

use std::sync::OnceLock;

use crate::pages::advise_huge_pages;

/// How far back a DEFLATE back-reference may reach.
pub(crate) const WINDOW: usize = 32 * 1024;
/// Longest match.
const MAX_MATCH: usize = 258;
/// Values a copy may write past its end (it copies 8 at a time).
const SLACK: usize = 8;

/// Bits of a byte slice, least significant bit of each byte first, read through a 64-bit buffer.
/// Past the end of the data it reads zeros; `overrun` tells.
#[derive(Clone, Copy)]
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
        bits.consume((pos % 8) as u32);
        bits
    }

    /// Bit position of the next bit.
    fn pos(&self) -> usize {
        8 * self.next - self.count as usize
    }

    /// Whether bits past the end of the data were consumed.
    fn overrun(&self) -> bool {
        self.pos() > 8 * self.data.len()
    }

    /// Fill the buffer to at least 56 bits.
    #[inline(always)]
    fn refill(&mut self) {
        if let Some(eight) = self.data.get(self.next..).and_then(|rest| rest.first_chunk::<8>()) {
            self.buffer |= u64::from_le_bytes(*eight) << self.count;
            self.next += ((63 - self.count) / 8) as usize;
            self.count |= 56;
        } else {
            while self.count <= 56 {
                self.buffer |= u64::from(self.data.get(self.next).copied().unwrap_or(0)) << self.count;
                self.next += 1;
                self.count += 8;
            }
        }
    }

    /// Drop `n` bits (at most what the buffer holds).
    #[inline(always)]
    fn consume(&mut self, n: u32) {
        self.buffer >>= n;
        self.count -= n;
    }

    /// Consume `n` (at most 32) bits; None past the end of the data.
    fn take(&mut self, n: u32) -> Option<u32> {
        if self.count < n {
            self.refill();
        }
        let value = (self.buffer & ((1u64 << n) - 1)) as u32;
        self.consume(n);
        (!self.overrun()).then_some(value)
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

// A table entry: bits 0-3 the code length (0: no code starts with these bits), 4-6 flags,
// 8-11 extra bits to read after the code (or a subtable's index bits), 16-31 a value (a
// literal, a length or distance base, a code-length symbol, or where a subtable starts).
const LITERAL: u32 = 1 << 4;
const END_OF_BLOCK: u32 = 1 << 5;
const SUBTABLE: u32 = 1 << 6;

const fn entry(value: u32, extra: u8, flags: u32) -> u32 {
    value << 16 | (extra as u32) << 8 | flags
}

/// A canonical Huffman code as a lookup table on its first `main_bits` bits, with subtables on
/// the bits after them for longer codes (a single table on 15 bits would not stay in cache).
struct Huffman {
    table: Vec<u32>,
    main_bits: u32,
}

impl Huffman {
    /// The code for `lengths` (0: symbol unused), with `meaning(symbol)` in each entry (0: the
    /// symbol may not occur), and whether the code is complete, has a single code, or is empty.
    /// None when the lengths over-subscribe the code space.
    fn new(lengths: &[u8], main_bits: u32, meaning: impl Fn(usize) -> u32) -> Option<(Huffman, Shape)> {
        let (count, complete) = kraft(lengths)?;
        let codes: u32 = count.iter().sum();
        let shape = if complete {
            Shape::Complete
        } else if codes == 0 {
            Shape::Empty
        } else if codes == 1 && count[1] == 1 {
            Shape::SingleBit
        } else {
            Shape::Incomplete
        };
        let longest = (1..16).rev().find(|&l| count[l] > 0).unwrap_or(1) as u32;
        let main_bits = main_bits.min(longest);
        let mut next = [0u32; 16];
        let mut code = 0;
        for bits in 1..16 {
            code = (code + count[bits - 1]) << 1;
            next[bits] = code;
        }
        // codes least significant bit first, as they are read
        let reversed: Vec<u32> = lengths
            .iter()
            .map(|&length| {
                let length = usize::from(length);
                if length == 0 {
                    return 0;
                }
                next[length] += 1;
                (next[length] - 1).reverse_bits() >> (32 - length)
            })
            .collect();
        let main_mask = (1u32 << main_bits) - 1;
        let mut table = vec![0u32; 1 << main_bits];
        // a subtable per main-table slot that starts longer codes, as deep as the longest one
        let mut depth = vec![0u8; 1 << main_bits];
        for (&length, &code) in lengths.iter().zip(&reversed) {
            if u32::from(length) > main_bits {
                let slot = &mut depth[(code & main_mask) as usize];
                *slot = (*slot).max(length - main_bits as u8);
            }
        }
        for (slot, &bits) in depth.iter().enumerate() {
            if bits > 0 {
                table[slot] = entry(table.len() as u32, bits, SUBTABLE);
                table.resize(table.len() + (1 << bits), 0);
            }
        }
        for (symbol, (&length, &code)) in lengths.iter().zip(&reversed).enumerate() {
            let length = u32::from(length);
            if length == 0 {
                continue;
            }
            let meant = meaning(symbol);
            let value = if meant == 0 { 0 } else { meant | length };
            let (start, slots, step, low) = if length <= main_bits {
                (0, 1usize << main_bits, 1usize << length, code as usize)
            } else {
                let head = table[(code & main_mask) as usize];
                let sub_bits = (head >> 8) & 15;
                ((head >> 16) as usize, 1 << sub_bits, 1 << (length - main_bits), (code >> main_bits) as usize)
            };
            for slot in (low..slots).step_by(step) {
                table[start + slot] = value;
            }
        }
        Some((Huffman { table, main_bits }, shape))
    }

    /// The entry for the code at the front of `buffer` (which holds at least 15 bits).
    #[inline(always)]
    fn lookup(&self, buffer: u64) -> u32 {
        let entry = self.table[(buffer & ((1 << self.main_bits) - 1)) as usize];
        if entry & SUBTABLE == 0 {
            return entry;
        }
        let index = (buffer >> self.main_bits) & ((1 << ((entry >> 8) & 15)) - 1);
        self.table[(entry >> 16) as usize + index as usize]
    }

    /// Read one code; its entry, None for bits that start no code.
    #[inline(always)]
    fn decode(&self, bits: &mut Bits<'_>) -> Option<u32> {
        let entry = self.lookup(bits.buffer);
        let length = entry & 15;
        if length == 0 {
            return None;
        }
        bits.consume(length);
        Some(entry)
    }
}

/// How a set of code lengths fills the code space.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Shape {
    Complete,
    Incomplete,
    /// one code of one bit: zlib accepts it
    SingleBit,
    /// no code at all: zlib accepts it for distances
    Empty,
}

const LENGTH_BASE: [u16; 29] = [3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258];
const LENGTH_EXTRA: [u8; 29] = [0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0];
const DISTANCE_BASE: [u16; 30] = [
    1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577,
];
const DISTANCE_EXTRA: [u8; 30] = [0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13];
/// Order in which a dynamic header lists the code lengths of the code-length alphabet.
const CODE_LENGTH_ORDER: [usize; 19] = [16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15];

/// Table entry meanings of the three alphabets.
fn literal_or_length(symbol: usize) -> u32 {
    match symbol {
        0..=255 => entry(symbol as u32, 0, LITERAL),
        256 => END_OF_BLOCK,
        257..=285 => entry(u32::from(LENGTH_BASE[symbol - 257]), LENGTH_EXTRA[symbol - 257], 0),
        _ => 0,
    }
}

fn distance(symbol: usize) -> u32 {
    match symbol {
        0..=29 => entry(u32::from(DISTANCE_BASE[symbol]), DISTANCE_EXTRA[symbol], 0),
        _ => 0,
    }
}

fn code_length(symbol: usize) -> u32 {
    entry(symbol as u32, 0, LITERAL)
}

/// Main-table bits of the literal/length and distance codes (libdeflate's choice).
const LITERAL_BITS: u32 = 10;
const DISTANCE_BITS: u32 = 8;

/// The codes of one block, after its header.
enum Block {
    Stored(usize),
    Coded { literals: Huffman, distances: Huffman },
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
            let literals = Huffman::new(&lengths, LITERAL_BITS, literal_or_length)?.0;
            let distances = Huffman::new(&[5u8; 32], DISTANCE_BITS, distance)?.0;
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
            let code_length_code = Huffman::new(&code_lengths, 7, code_length)?.0;
            let mut lengths = [0u8; 286 + 30];
            let total = literal_count + distance_count;
            let mut i = 0;
            while i < total {
                bits.refill();
                let (value, repeat) = match code_length_code.decode(bits)? >> 16 {
                    symbol @ 0..=15 => (symbol as u8, 1),
                    16 => (*lengths[..i].last()?, 3 + bits.take(2)? as usize),
                    17 => (0, 3 + bits.take(3)? as usize),
                    _ => (0, 11 + bits.take(7)? as usize),
                };
                lengths.get_mut(i..i + repeat)?.fill(value);
                i += repeat;
            }
            if i != total || lengths[256] == 0 || bits.overrun() {
                return None;
            }
            let (literals, shape) = Huffman::new(&lengths[..literal_count], LITERAL_BITS, literal_or_length)?;
            let (distances, distance_shape) = Huffman::new(&lengths[literal_count..total], DISTANCE_BITS, distance)?;
            let usable = matches!(shape, Shape::Complete | Shape::SingleBit)
                && matches!(distance_shape, Shape::Complete | Shape::SingleBit | Shape::Empty);
            usable.then_some((last, Block::Coded { literals, distances }))
        }
        _ => None,
    }
}

/// Output being decoded from the middle of a stream.
struct Speculative {
    /// The WINDOW markers, then what was decoded, then room for more and a copy's slack.
    values: Vec<u16>,
    /// end of what was decoded
    end: usize,
    /// `end` may not pass this
    limit_end: usize,
    /// past this, give up unless the last WINDOW values are free of markers
    give_up_end: usize,
}

impl Speculative {
    fn new(limit: Limit) -> Self {
        let mut values = Vec::with_capacity(4 * WINDOW);
        values.extend((0..WINDOW).map(|w| (256 + w) as u16));
        values.resize(4 * WINDOW, 0);
        let mut speculative = Speculative { values, end: WINDOW, limit_end: 0, give_up_end: 0 };
        speculative.set_limit(limit);
        speculative
    }

    /// Where `end` may go before `checkpoint` must run: a match and a copy's slack from the end
    /// of `values`, the limit, or the point to give up at.
    fn room_end(&self) -> usize {
        (self.values.len() - MAX_MATCH - SLACK).min(self.limit_end).min(self.give_up_end)
    }

    /// `end` passed `room_end`: None past the limit, or where markers persist past the point to
    /// give up at; else make room.
    fn checkpoint(&mut self) -> Option<()> {
        if self.end > self.limit_end {
            return None;
        }
        if self.end > self.give_up_end {
            if !self.clean() {
                return None;
            }
            self.give_up_end = usize::MAX;
        }
        self.reserve(MAX_MATCH + SLACK)
    }

    /// Room for `more` values past `end`, within the limit.
    fn reserve(&mut self, more: usize) -> Option<()> {
        if self.end + more > self.limit_end + MAX_MATCH + SLACK {
            return None;
        }
        // Doubling, zeroing as it grows rather than all up front (a big zeroed allocation is only
        // free where the allocator maps fresh pages, which glibc stops doing after a few frees).
        // A refused allocation ends decoding, as a limit does: the caller inflates in one piece.
        while self.end + more > self.values.len() {
            let grown = 2 * self.values.len();
            self.values.try_reserve_exact(grown - self.values.len()).ok()?;
            advise_huge_pages(&self.values);
            self.values.resize(grown, 0);
        }
        Some(())
    }

    /// Forget what was decoded.
    fn restart(&mut self) {
        self.end = WINDOW;
    }

    fn set_limit(&mut self, limit: Limit) {
        self.limit_end = WINDOW + limit.values;
        self.give_up_end = limit.give_up_after.map_or(usize::MAX, |after| WINDOW + after);
    }

    /// What was decoded, past the window.
    fn decoded(&self) -> usize {
        self.end - WINDOW
    }

    /// Decode the body of one block; None on anything a valid stream cannot hold.
    fn block(&mut self, bits: &mut Bits<'_>, block: &Block) -> Option<()> {
        let (literals, distances) = match block {
            Block::Stored(length) => {
                let start = bits.pos() / 8;
                let bytes = bits.data.get(start..start + length)?;
                self.reserve(*length)?;
                let to = &mut self.values[self.end..self.end + length];
                to.iter_mut().zip(bytes).for_each(|(value, &byte)| *value = u16::from(byte));
                self.end += length;
                return bits.skip(8 * length);
            }
            Block::Coded { literals, distances } => (literals, distances),
        };
        // locals, so that the loop keeps them in registers
        let mut local = *bits;
        let result = self.coded(&mut local, literals, distances);
        *bits = local;
        result
    }

    /// The body of a block with Huffman codes. `end` is kept up to date on every way out, so
    /// that what a failed candidate decoded counts against the block search's budget.
    fn coded(&mut self, bits: &mut Bits<'_>, literals: &Huffman, distances: &Huffman) -> Option<()> {
        let mut room_end = self.room_end();
        let mut values = &mut self.values[..];
        let mut end = self.end;
        // The entry of the next code is looked up as soon as its bits are in the buffer, so
        // that the lookup overlaps the work on the symbol before (as libdeflate does).
        bits.refill();
        let mut symbol = literals.lookup(bits.buffer);
        let result = loop {
            if end > room_end {
                self.end = end;
                if self.checkpoint().is_none() {
                    break None;
                }
                room_end = self.room_end();
                values = &mut self.values[..];
            }
            // the buffer holds at least 56 bits here: enough for a length code, its extra bits,
            // a distance code and its extra bits
            let length = symbol & 15;
            if length == 0 {
                break None;
            }
            bits.consume(length);
            if symbol & LITERAL != 0 {
                values[end] = (symbol >> 16) as u16;
                end += 1;
                bits.refill();
                symbol = literals.lookup(bits.buffer);
                continue;
            }
            if symbol & END_OF_BLOCK != 0 {
                break (!bits.overrun()).then_some(());
            }
            let extra = (symbol >> 8) & 15;
            let length = (symbol >> 16) as usize + (bits.buffer & ((1 << extra) - 1)) as usize;
            bits.consume(extra);
            let Some(code) = distances.decode(bits) else { break None };
            let extra = (code >> 8) & 15;
            let distance = (code >> 16) as usize + (bits.buffer & ((1 << extra) - 1)) as usize;
            bits.consume(extra);
            bits.refill();
            symbol = literals.lookup(bits.buffer);
            // the window holds WINDOW values, so a valid distance never reaches before it
            let Some(from) = end.checked_sub(distance) else { break None };
            copy(values, from, end, length);
            end += length;
        };
        self.end = end;
        result
    }


    /// The last WINDOW values hold no marker.
    fn clean(&self) -> bool {
        // from the end: where markers persist, one is usually near it
        self.values[self.end - WINDOW..self.end].rchunks(1024).all(|chunk| chunk.iter().fold(0, |any, &v| any | v) < 256)
    }
}

/// Append `length` values from `from` at `to` (`from < to`); may write SLACK values past the end.
#[inline(always)]
fn copy(values: &mut [u16], from: usize, to: usize, length: usize) {
    let distance = to - from;
    if distance >= SLACK {
        // each chunk reads values already in place: the source ends at or before the destination
        values.copy_within(from..from + SLACK, to);
        let mut k = SLACK;
        while k < length {
            values.copy_within(from + k..from + k + SLACK, to + k);
            k += SLACK;
        }
    } else if distance == 1 {
        let value = values[from];
        values[to..to + length].fill(value);
    } else {
        // the output repeats with period `distance`
        for k in 0..length {
            values[to + k] = values[from + k];
        }
    }
}

/// How far the marker decoder may go.
#[derive(Clone, Copy)]
pub(crate) struct Limit {
    /// most values to decode
    pub values: usize,
    /// give up past this many values while the last WINDOW hold a marker
    pub give_up_after: Option<usize>,
}

impl Limit {
    pub fn values(values: usize) -> Self {
        Limit { values, give_up_after: None }
    }
}

/// Where decoding from the middle stopped.
pub(crate) struct Partial {
    /// The WINDOW markers `256 + w`, then the bytes (< 256) and markers decoded from the start.
    values: Vec<u16>,
    /// Bit position of the block boundary where decoding stopped.
    pub stop: usize,
    /// Decoding reached `end` or the final block: nothing is left for libdeflate.
    pub finished: bool,
    /// Otherwise the WINDOW bytes before `stop`, for the inflater that goes on from there.
    pub window: Vec<u8>,
}

impl Partial {
    /// Bytes (< 256) and window markers (`256 + w`) decoded from the start.
    pub fn output(&self) -> &[u16] {
        &self.values[WINDOW..]
    }
}

/// A block start, and its first block already decoded where `find_block` did that as its test.
pub(crate) struct Found {
    /// bit position of the block start
    pub start: usize,
    /// the values of the first block, and the bit position after it
    first_block: Option<(Speculative, usize)>,
}

impl Found {
    /// A block start known to be one.
    pub fn at(start: usize) -> Self {
        Found { start, first_block: None }
    }
}

/// Decode from the block start `from` until the last WINDOW bytes hold no marker (at a block
/// boundary), or until bit `end` (a block boundary), or past the final block. Once `preceding`
/// holds the WINDOW bytes before the start (another thread decodes them), decoding stops at the
/// next block boundary (the markers are left for the caller to fill in). None when the data is
/// not a valid stream from the start, when decoding passes `end` without stopping on it, or when
/// `limit` is passed.
pub(crate) fn decode_from(data: &[u8], from: Found, end: usize, limit: Limit, preceding: &OnceLock<Vec<u8>>) -> Option<Partial> {
    let (mut decoded, mut bits, mut last) = match from.first_block {
        Some((decoded, after)) => (decoded, Bits::at(data, after), false),
        None => {
            let mut decoded = Speculative::new(limit);
            let mut bits = Bits::at(data, from.start);
            let (last, block) = read_header(&mut bits)?;
            decoded.block(&mut bits, &block)?;
            (decoded, bits, last)
        }
    };
    decoded.set_limit(limit);
    loop {
        let known = preceding.get().filter(|window| window.len() == WINDOW);
        let finished = last || bits.pos() == end;
        if finished || known.is_some() || decoded.clean() {
            let tail = &decoded.values[decoded.end - WINDOW..decoded.end];
            let window = match known {
                _ if finished => Vec::new(),
                Some(known) => tail.iter().map(|&v| if v < 256 { v as u8 } else { known[usize::from(v - 256)] }).collect(),
                None => tail.iter().map(|&v| v as u8).collect(),
            };
            let mut values = decoded.values;
            values.truncate(decoded.end);
            return Some(Partial { values, stop: bits.pos(), finished, window });
        }
        if bits.pos() > end {
            return None;
        }
        let (is_last, block) = read_header(&mut bits)?;
        decoded.block(&mut bits, &block)?;
        last = is_last;
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
const TABLE_COST: usize = 1 << 12;

/// A cheap test of the first 56 bits of a dynamic block header (not final): at most 286
/// literal/length and 30 distance codes, and a code-length code that is complete as far as its
/// lengths are in these bits.
fn plausible_dynamic(word: u64) -> bool {
    if (word >> 3) & 31 > 29 || (word >> 8) & 31 > 29 {
        return false;
    }
    let listed = ((word >> 13) & 15) as usize + 4;
    // 3-bit lengths from bit 17: 13 of them fit in 56 bits
    let seen = listed.min(13);
    let space: u32 = (0..seen).map(|i| (word >> (17 + 3 * i)) & 7).filter(|&length| length != 0).map(|length| 128 >> length).sum();
    if listed == seen { space == 128 } else { space <= 128 }
}

/// A cheap test of a stored block header (not final) at bit `start`: the length at the next
/// byte boundary is followed by its complement.
fn plausible_stored(data: &[u8], start: usize) -> bool {
    let at = (start + 3).div_ceil(8);
    data.get(at..at + 4).is_some_and(|b| u16::from_le_bytes([b[0], b[1]]) == !u16::from_le_bytes([b[2], b[3]]))
}

/// The first block start found in `from..to`: of a block with its own Huffman codes whose header
/// is valid and whose body decodes, followed by a valid block header; or of the block after a
/// stored block whose body follows (a stored header is only 35 bits and a 16-bit check) by a
/// block that decodes. A stored block's own start is ambiguous (its header may sit anywhere in
/// the zero bits before its byte boundary), so the block after it is taken.
pub(crate) fn find_block(data: &[u8], from: usize, to: usize) -> Option<Found> {
    let to = to.min(8 * data.len()).min(from + 8 * SEARCH_BYTES);
    // Crafted data could make many starts look valid for long: bound the work over all of them
    // (a candidate past its header costs its tables and the bytes it decodes).
    let mut budget = SEARCH_BUDGET;
    let mut decoded = Speculative::new(Limit::values(BLOCK_LIMIT));
    for start in from..to {
        // cheap tests first: most bit positions fail them
        let word = data.get(start / 8..).and_then(|rest| rest.first_chunk::<8>()).map_or(0, |eight| u64::from_le_bytes(*eight) >> (start % 8));
        let dynamic = match word & 7 {
            0b100 if plausible_dynamic(word) => true,
            0b000 if plausible_stored(data, start) => false,
            _ => continue,
        };
        let mut bits = Bits::at(data, start);
        let Some((false, block)) = read_header(&mut bits) else { continue };
        decoded.restart();
        decoded.limit_end = WINDOW + BLOCK_LIMIT.min(budget);
        let found = decoded.block(&mut bits, &block).and_then(|()| {
            let after = bits.pos();
            let (_, next) = read_header(&mut bits)?;
            if !dynamic {
                decoded.block(&mut bits, &next)?;
            }
            Some(after)
        });
        match found {
            // the block's values come along to be decoded on from
            Some(after) if dynamic => return Some(Found { start, first_block: Some((decoded, after)) }),
            Some(after) => return Some(Found::at(after)),
            None => {}
        }
        budget = budget.checked_sub(TABLE_COST + decoded.decoded())?;
    }
    None
}

/// Bits written least significant first, as DEFLATE stores them.
pub(crate) struct BitWriter {
    pub bytes: Vec<u8>,
    pub bits: usize,
}

impl BitWriter {
    pub fn with_capacity(bytes: usize) -> Self {
        BitWriter { bytes: Vec::with_capacity(bytes), bits: 0 }
    }

    /// The low `n` (at most 24) bits of `value`.
    pub fn put(&mut self, value: u32, n: u32) {
        let shift = (self.bits % 8) as u32;
        let mut pending = (value & ((1 << n) - 1)) << shift;
        if let Some(partial) = self.bytes.last_mut().filter(|_| shift != 0) {
            *partial |= pending as u8;
            pending >>= 8;
        }
        let new_bytes = (shift + n).div_ceil(8) - u32::from(shift != 0);
        for _ in 0..new_bytes {
            self.bytes.push(pending as u8);
            pending >>= 8;
        }
        self.bits += n as usize;
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
        let partial = decode_from(&compressed, Found::at(0), usize::MAX, Limit::values(data.len()), &OnceLock::new()).unwrap_or_else(|| unreachable!());
        // stops once 32 KiB are clean; what it has matches the data
        assert!(partial.output().len() >= WINDOW && partial.output().len() < data.len());
        assert!(partial.output().iter().zip(&data).all(|(&a, &b)| a == u16::from(b)));
    }

    #[test]
    fn from_the_middle_markers_name_window_bytes() {
        let data = sample(2_000_000, 2);
        let compressed = deflate(&data, 6);
        let found = find_block(&compressed, 4 * compressed.len(), 8 * compressed.len()).unwrap_or_else(|| unreachable!());
        let start = found.start;
        let partial = decode_from(&compressed, found, usize::MAX, Limit::values(data.len()), &OnceLock::new()).unwrap_or_else(|| unreachable!());
        // where the block starts in the data: find it by decoding everything up to `start`
        let mut ending = compressed.clone();
        let used = end_stream_at(&mut ending, start);
        let mut head = vec![0; data.len()];
        let offset = libdeflater::Decompressor::new().deflate_decompress(&ending[..used], &mut head).unwrap_or_else(|e| unreachable!("{e}"));
        assert!(offset > WINDOW && offset < data.len());
        assert!(partial.output().iter().any(|&v| v >= 256), "text this repetitive refers back across the start");
        for (i, &v) in partial.output().iter().enumerate() {
            let expected = data[offset + i];
            let got = if v < 256 { v as u8 } else { data[offset - WINDOW + usize::from(v - 256)] };
            assert_eq!(got, expected, "at {i}");
        }
        // with the bytes before the start known, decoding stops after the first block, and the
        // window handed on has its markers filled in
        let known = OnceLock::from(data[offset - WINDOW..offset].to_vec());
        let resolved = decode_from(&compressed, Found::at(start), usize::MAX, Limit::values(data.len()), &known).unwrap_or_else(|| unreachable!());
        assert!(resolved.output().len() < partial.output().len());
        assert_eq!(resolved.output(), &partial.output()[..resolved.output().len()]);
        let stop = offset + resolved.output().len();
        assert_eq!(resolved.window, data[stop - WINDOW..stop]);
    }

    #[test]
    fn stored_blocks_are_found_too() {
        let data = sample(400_000, 3);
        let stored = deflate(&data, 0);
        let found = find_block(&stored, 8 * 100_000, 8 * stored.len()).unwrap_or_else(|| unreachable!());
        let start = found.start;
        let partial = decode_from(&stored, found, usize::MAX, Limit::values(data.len()), &OnceLock::new()).unwrap_or_else(|| unreachable!());
        // the block after a stored one starts on a byte, and stored blocks need no window
        assert_eq!(start % 8, 0);
        let offset = data.windows(64).position(|w| w.iter().zip(partial.output()).all(|(&a, &b)| u16::from(a) == b));
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
        assert!(find_block(&noise, 0, 8 * noise.len()).is_none());
    }

    #[test]
    fn codes_of_every_length_decode_through_both_table_levels() {
        // one symbol for each length 1..=15 and a second of 15: a complete code, whose codes
        // longer than LITERAL_BITS go through subtables
        let mut lengths: Vec<u8> = (1..=15).collect();
        lengths.push(15);
        let (code, shape) = Huffman::new(&lengths, LITERAL_BITS, literal_or_length).unwrap_or_else(|| unreachable!());
        assert!(shape == Shape::Complete);
        for (symbol, &length) in lengths.iter().enumerate() {
            // canonical: length l < 15 is 1..10 (l bits); the two of 15 bits are 1..10 and 1..11
            let canonical = if symbol < 15 { (1u32 << length) - 2 } else { (1 << 15) - 1 };
            let mut writer = BitWriter::with_capacity(64);
            writer.put_code(canonical, u32::from(length));
            writer.put(0x5A5A, 16); // bits after the code must not matter
            let mut bits = Bits::at(&writer.bytes, 0);
            let entry = code.decode(&mut bits).unwrap_or_else(|| unreachable!("symbol {symbol}"));
            assert_eq!(entry >> 16, symbol as u32);
            assert!(entry & LITERAL != 0);
            assert_eq!(bits.pos(), usize::from(length), "symbol {symbol}");
        }
        // an incomplete code leaves holes that decode to nothing
        let (holes, shape) = Huffman::new(&[2, 2, 2], LITERAL_BITS, literal_or_length).unwrap_or_else(|| unreachable!());
        assert!(shape == Shape::Incomplete);
        let mut bits = Bits::at(&[0xFF, 0xFF], 0);
        assert!(holes.decode(&mut bits).is_none());
    }

    #[test]
    fn a_found_start_decodes_on_from_its_first_block() {
        let data = sample(2_000_000, 4);
        let compressed = deflate(&data, 9);
        let found = find_block(&compressed, 4 * compressed.len(), 8 * compressed.len()).unwrap_or_else(|| unreachable!());
        let start = found.start;
        let limit = Limit::values(data.len());
        let reused = decode_from(&compressed, found, usize::MAX, limit, &OnceLock::new()).unwrap_or_else(|| unreachable!());
        let fresh = decode_from(&compressed, Found::at(start), usize::MAX, limit, &OnceLock::new()).unwrap_or_else(|| unreachable!());
        assert_eq!(reused.output(), fresh.output());
        assert_eq!((reused.stop, reused.finished, &reused.window), (fresh.stop, fresh.finished, &fresh.window));
    }

    #[test]
    fn fixed_literals_round_trip_through_libdeflate() {
        let mut writer = BitWriter::with_capacity(64);
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

