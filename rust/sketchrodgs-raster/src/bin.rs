//! Depth sort and tile binning (INRIA `duplicateWithKeys` + radix sort + `identifyTileRanges`).
//!
//! The reference sorts `(tile << 32 | depth bits)` keys, stable, emitted in Gaussian order, so a
//! tile's list runs front to back with equal depths in ascending index. We get the same lists by
//! sorting the visible Gaussians once by `(depth, index)` and then distributing them, in that
//! order, into per-tile lists. The distribution runs on contiguous chunks of the depth order in
//! parallel, each chunk keeping its own lists; a tile's list is the concatenation of its chunk
//! lists in chunk order, which is again front to back. No step depends on the thread count.

use rayon::prelude::*;

use crate::camera::Camera;
use crate::kept;
use crate::project::{MIN_GAUSSIANS_PER_TASK, Projected};
use crate::tiles::TileMask;
use crate::tiles::TileRect;
use crate::{RasterError, try_filled};

/// Most per-chunk tile counters kept in memory at once (chunks x tiles).
const MAX_CHUNK_COUNTERS: usize = 1 << 22;
/// Sorted Gaussians per binning chunk.
const GAUSSIANS_PER_CHUNK: usize = 16384;

/// The visible (non-culled) Gaussians, front to back: sorted by camera z, ties by ascending
/// index (the order the reference's stable key sort gives).
pub fn sort_by_depth(projected: &Projected) -> Vec<u32> {
    // z > camera.near > 0 (a sort point's z >= 0), so the f32 bit pattern orders like the value.
    // Keys are made in index order (rayon's collect keeps it) and the sort is stable, so equal
    // depths stay in ascending index. Culled entries get no key: a view of part of a large scene
    // sorts only what it sees.
    let mut keys = kept::SORT_KEYS.take();
    keys.clear();
    keys.par_extend(
        (0..projected.rects.len()).into_par_iter().with_min_len(MIN_GAUSSIANS_PER_TASK).filter_map(|i| {
            (!projected.rects[i].is_empty()).then(|| (u64::from(projected.sort_key(i)) << 32) | i as u64)
        }),
    );
    radix_sort_by_high_word(&mut keys);
    let mut order = Vec::new();
    keys.par_iter().with_min_len(MIN_GAUSSIANS_PER_TASK).map(|k| *k as u32).collect_into_vec(&mut order);
    kept::SORT_KEYS.give_back(keys);
    order
}

/// Bits of the key sorted per radix pass: three passes cover the 32-bit depth, and a pass's
/// counters (8 KiB) stay in L1.
const RADIX_BITS: u32 = 11;
const RADIX: usize = 1 << RADIX_BITS;

/// Keys per task of a radix pass (at least; fewer, longer chunks on very long inputs).
const RADIX_CHUNK: usize = 1 << 18;
/// Most chunks a radix pass splits the keys into (each keeps `RADIX` cursors and slices).
const RADIX_MAX_CHUNKS: usize = 16;

/// Stable LSD radix sort of `keys` by their upper 32 bits, `RADIX_BITS` a pass: keys with equal
/// upper halves keep their input order. Passes where every key has the same digit are skipped.
///
/// Each pass runs on contiguous chunks in parallel: chunk c's keys of digit d go, in order, to
/// their own slice of the output, after those of every smaller digit and of digit d in earlier
/// chunks. That is the serial pass's placement, so the result does not depend on the chunking.
fn radix_sort_by_high_word(keys: &mut Vec<u64>) {
    const PASSES: usize = 32_u32.div_ceil(RADIX_BITS) as usize;
    let digit = |k: u64, pass: usize| (k >> (32 + RADIX_BITS as usize * pass)) as usize & (RADIX - 1);
    let chunk_len = RADIX_CHUNK.max(keys.len().div_ceil(RADIX_MAX_CHUNKS)).max(1);
    let count = |keys: &[u64], pass: usize| -> Vec<Vec<usize>> {
        keys.par_chunks(chunk_len)
            .map(|chunk| {
                let mut count = vec![0usize; RADIX];
                chunk.iter().for_each(|&k| count[digit(k, pass)] += 1);
                count
            })
            .collect()
    };
    let mut scratch = kept::with_len(kept::SORT_SCRATCH.take(), keys.len());
    for pass in 0..PASSES {
        let counts = count(keys, pass);
        if (0..RADIX).any(|d| counts.iter().map(|c| c[d]).sum::<usize>() == keys.len()) {
            continue;
        }
        // slots[c][d]: where chunk c puts its keys of digit d
        let mut slots: Vec<Vec<&mut [u64]>> = counts.iter().map(|_| Vec::with_capacity(RADIX)).collect();
        let mut rest = scratch.as_mut_slice();
        for d in 0..RADIX {
            for (chunk_slots, count) in slots.iter_mut().zip(&counts) {
                let (slot, tail) = std::mem::take(&mut rest).split_at_mut(count[d]);
                chunk_slots.push(slot);
                rest = tail;
            }
        }
        keys.par_chunks(chunk_len).zip(slots).for_each(|(chunk, mut slots)| {
            let mut cursor = vec![0usize; RADIX];
            for &k in chunk {
                let d = digit(k, pass);
                slots[d][cursor[d]] = k;
                cursor[d] += 1;
            }
        });
        std::mem::swap(keys, &mut scratch);
    }
    kept::SORT_SCRATCH.give_back(scratch);
}

/// The per-tile lists of Gaussian indices, front to back.
#[derive(Debug)]
pub struct TileBins {
    pub grid_x: u32,
    pub grid_y: u32,
    chunks: Vec<ChunkBins>,
}

/// The lists of one contiguous chunk of the sorted order: tile t owns
/// `entries[offsets[t]..offsets[t + 1]]`.
#[derive(Debug)]
struct ChunkBins {
    offsets: Vec<u32>,
    entries: Vec<u32>,
}

impl TileBins {
    /// Bins the Gaussians `order` (front to back) into the tiles of their `rects` (only the tiles
    /// of `mask`, when given); an error where the lists do not fit in memory.
    pub fn new(
        camera: &Camera,
        rects: &[TileRect],
        order: &[u32],
        mask: Option<&TileMask>,
    ) -> Result<Self, RasterError> {
        let (grid_x, grid_y) = camera.tile_grid();
        let n_tiles = (grid_x * grid_y) as usize;
        // Bound the counters' memory on very large images by using longer chunks.
        let max_chunks = (MAX_CHUNK_COUNTERS / n_tiles.max(1)).max(1);
        let chunk_len = GAUSSIANS_PER_CHUNK.max(order.len().div_ceil(max_chunks)).max(1);
        let chunks = order
            .par_chunks(chunk_len)
            .map(|chunk| ChunkBins::new(chunk, rects, grid_x, n_tiles, mask))
            .collect::<Result<_, _>>()?;
        Ok(Self { grid_x, grid_y, chunks })
    }

    /// Total number of (tile, Gaussian) pairs.
    pub fn len(&self) -> usize {
        self.chunks.iter().map(|c| c.entries.len()).sum()
    }

    /// Whether no Gaussian touches any tile.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Tile `tile`'s list, front to back, as consecutive slices of Gaussian indices.
    pub fn tile_lists(&self, tile: usize) -> impl Iterator<Item = &[u32]> + '_ {
        self.chunks.iter().filter_map(move |c| {
            let start = *c.offsets.get(tile)? as usize;
            let end = *c.offsets.get(tile + 1)? as usize;
            c.entries.get(start..end).filter(|s| !s.is_empty())
        })
    }
}

impl ChunkBins {
    fn new(
        order: &[u32],
        rects: &[TileRect],
        grid_x: u32,
        n_tiles: usize,
        mask: Option<&TileMask>,
    ) -> Result<Self, RasterError> {
        // The chunk's rectangles in its order, read once from the whole scene's at random: both
        // passes below then read them in sequence (binning 20-22 to 15 ms at capture size).
        let mut chunk_rects = try_filled(order.len(), TileRect::default(), "tile lists")?;
        for (r, &i) in chunk_rects.iter_mut().zip(order) {
            *r = rects.get(i as usize).copied().unwrap_or_default();
        }
        let tiles = |r: TileRect| {
            let grid_x = grid_x as usize;
            (r.y0..r.y1)
                .flat_map(move |ty| (r.x0..r.x1).map(move |tx| usize::from(ty) * grid_x + usize::from(tx)))
                .filter(move |&t| mask.is_none_or(|m| m.contains(t)))
        };
        // Counting sort by tile, stable in depth order.
        let mut offsets = try_filled(n_tiles + 1, 0u32, "tile lists")?;
        for &r in &chunk_rects {
            for t in tiles(r) {
                offsets[t + 1] += 1;
            }
        }
        for t in 0..n_tiles {
            offsets[t + 1] += offsets[t];
        }
        let mut cursor = offsets.clone();
        let mut entries = try_filled(offsets[n_tiles] as usize, 0u32, "tile lists")?;
        for (&i, &r) in order.iter().zip(&chunk_rects) {
            for t in tiles(r) {
                entries[cursor[t] as usize] = i;
                cursor[t] += 1;
            }
        }
        Ok(Self { offsets, entries })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn radix_sort_orders_by_depth_then_input_order() {
        let mut state = 7u64;
        let mut keys: Vec<u64> = (0..600_000u64) // several chunks of a pass
            .map(|i| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                // Few distinct depths, so ties are common; positive floats of all magnitudes.
                let depth = 0.2f32 + ((state >> 33) % 500) as f32 * 37.5;
                (u64::from(depth.to_bits()) << 32) | i
            })
            .collect();
        let mut expected = keys.clone();
        expected.sort_unstable();
        radix_sort_by_high_word(&mut keys);
        assert_eq!(keys, expected);
        let mut empty: Vec<u64> = vec![];
        radix_sort_by_high_word(&mut empty);
        assert!(empty.is_empty());
    }
}
