//! PlayCanvas / SuperSplat compressed PLY: splats in chunks of 256, each chunk with float bounds,
//! each splat packed into four u32 (position, rotation, scale, colour), optional u8 SH.
//!
//! - position: x, y, z as 11, 10, 11-bit fractions (x in the top bits) between the chunk's
//!   min and max; scale likewise, of the log scales.
//! - rotation: bits 30-31 the index (w, x, y, z order) of the largest component, then the other
//!   three, 10 bits each mapping [0, 1023] to [-1/sqrt(2), 1/sqrt(2)], the first the highest.
//! - colour: r, g, b, a bytes (r in the top byte); rgb = 0.5 + SH_C0 * f_dc, between the chunk's
//!   min and max colour when the file has colour bounds, else itself; a is the opacity.
//! - SH: f_rest bytes, channel-major; b stands for 8 * ((b + 0.5) / 256 - 0.5), 0 and 255 for -4, 4.
//!
//! Interpolation runs in f64, then rounds to f32, as the PlayCanvas decoder does in JavaScript.

use crate::{BLOCK, Block, SH_C0, SizeError, SplatsMut, check_len, smallest_three, table};

pub const CHUNK_SIZE: usize = 256;

/// Chunk bound columns, in this order: min x, y, z, max x, y, z, min scale x, y, z, max scale
/// x, y, z, and with colour bounds min r, g, b, max r, g, b.
pub const BOUNDS_WITHOUT_COLORS: usize = 12;
pub const BOUNDS_WITH_COLORS: usize = 18;

/// One file's arrays.
pub struct Packed<'a> {
    /// (chunks, 12 or 18) chunk bounds, row-major.
    pub bounds: &'a [f64],
    pub bound_columns: usize,
    /// Per splat four little-endian u32: position, rotation, scale, colour (bytes, as a file
    /// mapped into memory need not align them).
    pub splats: &'a [[u8; 16]],
    /// (N, 3 * (K - 1)) f_rest bytes, channel-major; empty when the file has no SH.
    pub sh_rest: &'a [u8],
}

/// Per-field values, worked out once per file. The fractions stay f64: the interpolation uses
/// them unrounded.
struct Tables {
    unit_11: Vec<f64>,
    unit_10: Vec<f64>,
    unit_8: Vec<f64>,
    rotation: Vec<f32>,
    sh: Vec<f32>,
}

/// Decode `packed` into `out`, whose `sh_coefficients` must match the SH bytes per splat.
pub fn decode(packed: &Packed<'_>, out: SplatsMut<'_>) -> Result<(), SizeError> {
    let n = out.count()?;
    if packed.bound_columns != BOUNDS_WITH_COLORS {
        check_len("chunk bound columns", packed.bound_columns, BOUNDS_WITHOUT_COLORS)?;
    }
    check_len("chunk bounds", packed.bounds.len(), n.div_ceil(CHUNK_SIZE) * packed.bound_columns)?;
    check_len("packed splats", packed.splats.len(), n)?;
    check_len("sh", packed.sh_rest.len(), 3 * (out.sh_coefficients - 1) * n)?;
    let tables = Tables {
        unit_11: fractions(2047),
        unit_10: fractions(1023),
        unit_8: fractions(255),
        rotation: table(1024, |i| (i / 1023.0 - 0.5) * std::f64::consts::SQRT_2),
        sh: table(256, |b| {
            let t = if b == 0.0 {
                0.0
            } else if b == 255.0 {
                1.0
            } else {
                (b + 0.5) / 256.0
            };
            8.0 * (t - 0.5)
        }),
    };
    // Whole chunks per block, so that no chunk is split between tasks.
    out.for_each_block(BLOCK / CHUNK_SIZE * CHUNK_SIZE, |block| decode_block(packed, &tables, block));
    Ok(())
}

fn decode_block(p: &Packed<'_>, t: &Tables, block: Block<'_>) {
    let first = block.start;
    let size = block.opacities.len();
    let rest = block.sh.len() / size.max(1) - 3; // f_rest values per splat
    let coefficients = rest / 3;
    for i in 0..size {
        let splat = first + i;
        let bounds = &p.bounds[splat / CHUNK_SIZE * p.bound_columns..][..p.bound_columns];
        let word = |i: usize| {
            let b = &p.splats[splat][4 * i..4 * i + 4];
            u32::from_le_bytes([b[0], b[1], b[2], b[3]])
        };
        let [position, rotation, scale, color] = [0, 1, 2, 3].map(word);
        // the PlayCanvas decoder's lerp: min * (1 - t) + max * t, in f64
        let lerp = |low: f64, high: f64, t: f64| low * (1.0 - t) + high * t;
        let fields = |packed: u32| {
            [
                t.unit_11[(packed >> 21) as usize & 0x7FF],
                t.unit_10[(packed >> 11) as usize & 0x3FF],
                t.unit_11[packed as usize & 0x7FF],
            ]
        };
        let (position, scale) = (fields(position), fields(scale));
        for axis in 0..3 {
            block.means[i][axis] = lerp(bounds[axis], bounds[3 + axis], position[axis]) as f32;
            // the log scale is rounded to f32, as an INRIA .ply stores it, so that the scene
            // written to .ply reads back with the same scales
            let log_scale = lerp(bounds[6 + axis], bounds[9 + axis], scale[axis]) as f32;
            block.scales[i][axis] = f64::from(log_scale).exp() as f32;
        }
        let field = |shift: u32| t.rotation[((rotation >> shift) & 0x3FF) as usize];
        block.quats[i] = smallest_three([field(20), field(10), field(0)], (rotation >> 30) as usize, [0, 1, 2, 3]);
        block.opacities[i] = (color & 0xFF) as f32 / 255.0;
        let sh = &mut block.sh[i * (rest + 3)..(i + 1) * (rest + 3)];
        for channel in 0..3 {
            let byte = ((color >> (24 - 8 * channel)) & 0xFF) as usize;
            let rgb = if p.bound_columns == BOUNDS_WITH_COLORS {
                lerp(bounds[12 + channel], bounds[15 + channel], t.unit_8[byte]) as f32
            } else {
                t.unit_8[byte] as f32
            };
            sh[channel] = (rgb - 0.5) / SH_C0 as f32;
        }
        // channel-major in the file: f_rest_{c*(K-1)+j} is basis j+1 of channel c
        let bytes = &p.sh_rest[rest * splat..rest * (splat + 1)];
        for j in 0..coefficients {
            for channel in 0..3 {
                sh[3 * (j + 1) + channel] = t.sh[usize::from(bytes[channel * coefficients + j])];
            }
        }
    }
}

/// i / max for i in 0..=max.
fn fractions(max: u32) -> Vec<f64> {
    (0..=max).map(|i| f64::from(i) / f64::from(max)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_splat_written_bit_by_bit() {
        let bounds =
            [0.0, -1.0, 10.0, 2047.0, 1.0, 20.0, -5.0, -5.0, -5.0, -1.0, -3.0, -5.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.5];
        let position: u32 = (2047 << 21) | 1023; // x = max, y = min, z = 1023/2047 of the range
        let rotation: u32 = (2 << 30) | (1023 << 20) | 512; // largest is rot_2 (y)
        let scale: u32 = (1023 << 11) | 2047;
        let color: u32 = (255 << 24) | (128 << 8) | 64;
        let mut splat = [0u8; 16];
        for (i, word) in [position, rotation, scale, color].iter().enumerate() {
            splat[4 * i..4 * i + 4].copy_from_slice(&word.to_le_bytes());
        }
        let rest = [0, 255, 128, 1, 2, 3, 4, 5, 6];
        let packed = Packed { bounds: &bounds, bound_columns: BOUNDS_WITH_COLORS, splats: &[splat], sh_rest: &rest };
        let (mut means, mut scales, mut quats, mut opacities, mut sh) =
            (vec![0.0; 3], vec![0.0; 3], vec![0.0; 4], vec![0.0; 1], vec![0.0; 12]);
        let out = SplatsMut {
            means: &mut means,
            scales: &mut scales,
            quats: &mut quats,
            opacities: &mut opacities,
            sh: &mut sh,
            sh_coefficients: 4,
        };
        decode(&packed, out).unwrap_or_else(|e| unreachable!("{e}"));
        assert_eq!(means, [2047.0, -1.0, (10.0 + 10.0 * 1023.0 / 2047.0) as f32]);
        assert_eq!(scales, [(-5.0_f64).exp() as f32, (-3.0_f64).exp() as f32, (-5.0_f64).exp() as f32]);
        assert_eq!(opacities, [64.0 / 255.0]);
        // colours lerp between the chunk's colour bounds: r = 1, g = 0, b = 0.5 * 128/255
        let rgb = [1.0_f32, 0.0, (0.5 * 128.0 / 255.0) as f32];
        let dc: Vec<f32> = rgb.iter().map(|c| (c - 0.5) / SH_C0 as f32).collect();
        assert_eq!(&sh[..3], dc.as_slice());
        // |stored| > 1: the largest component is 0 and the quaternion rescaled
        let (a, b, c) = (
            0.5 * std::f64::consts::SQRT_2,
            -0.5 * std::f64::consts::SQRT_2,
            (512.0 / 1023.0 - 0.5) * std::f64::consts::SQRT_2,
        );
        let norm = (a * a + b * b + c * c).sqrt();
        assert!(quats.iter().zip([a / norm, b / norm, 0.0, c / norm]).all(|(&q, e)| (f64::from(q) - e).abs() < 2e-6));
        // channel-major bytes: f_rest_{c*3+j} is basis j+1 of channel c; 0 and 255 are -4 and 4
        let value = |b: f64| 8.0 * ((b + 0.5) / 256.0 - 0.5);
        let expected =
            [[-4.0, value(1.0), value(4.0)], [4.0, value(2.0), value(5.0)], [value(128.0), value(3.0), value(6.0)]];
        for (j, row) in expected.iter().enumerate() {
            for (channel, &e) in row.iter().enumerate() {
                assert_eq!(sh[3 * (j + 1) + channel], e as f32);
            }
        }
    }
}
