//! Niantic SPZ attributes (versions 2 to 4) once inflated: six blocks, each for all splats in
//! turn. Positions are 3 x 24-bit signed fixed point; alphas u8 (sigmoid already applied);
//! colours 3 x u8 holding 0.5 + 0.15 * f_dc; scales 3 x u8 holding (log scale + 10) * 16;
//! rotations (see [`Rotations`]); SH as u8 holding 128 + 128 * coefficient, coefficient-major
//! with RGB inner, the same order as our (K, 3) rows.

use crate::{BLOCK, Block, SizeError, SplatsMut, check_len, smallest_three, table};

/// SPZ keeps f_dc as 0.5 + 0.15 * f_dc so that colours a little outside [0, 1] fit.
const COLOR_SCALE: f64 = 0.15;

/// How a version stores rotations.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rotations {
    /// Version 2: x, y, z as u8 (q / 127.5 - 1), w >= 0 rebuilt.
    XyzBytes,
    /// Versions 3 and 4: a little-endian u32, bits 30-31 the index (x, y, z, w order) of the
    /// largest component, then 10 bits for each other one (9-bit magnitude over 1/sqrt(2) and a
    /// sign bit), the first of them in the highest bits.
    SmallestThree,
}

impl Rotations {
    /// Bytes per splat in the rotation block.
    pub fn bytes(self) -> usize {
        match self {
            Rotations::XyzBytes => 3,
            Rotations::SmallestThree => 4,
        }
    }
}

/// The inflated attribute blocks of one file.
pub struct Attributes<'a> {
    pub positions: &'a [u8],
    pub alphas: &'a [u8],
    pub colors: &'a [u8],
    pub scales: &'a [u8],
    pub rotations: &'a [u8],
    /// `sh_bytes_per_splat` bytes per splat; bands beyond the output's degree are skipped.
    pub sh: &'a [u8],
    pub sh_bytes_per_splat: usize,
    pub fractional_bits: u8,
    pub rotation_format: Rotations,
}

impl<'a> Attributes<'a> {
    /// The six blocks of `payload`, the attribute bytes of `count` splats in file order.
    pub fn split(
        payload: &'a [u8],
        count: usize,
        rotation_format: Rotations,
        sh_bytes_per_splat: usize,
        fractional_bits: u8,
    ) -> Result<Self, SizeError> {
        let widths = [9, 1, 3, 3, rotation_format.bytes(), sh_bytes_per_splat];
        check_len("SPZ payload", payload.len(), widths.iter().sum::<usize>() * count)?;
        let mut rest = payload;
        let [positions, alphas, colors, scales, rotations, sh] = widths.map(|width| {
            let (block, after) = rest.split_at(width * count);
            rest = after;
            block
        });
        Ok(Attributes {
            positions,
            alphas,
            colors,
            scales,
            rotations,
            sh,
            sh_bytes_per_splat,
            fractional_bits,
            rotation_format,
        })
    }
}

/// Per-byte values, worked out once per file.
struct Tables {
    dc: Vec<f32>,
    scale: Vec<f32>,
    v2_rotation: Vec<f32>,
    smallest_three: Vec<f32>,
    position_scale: f32,
}

impl Tables {
    fn new(fractional_bits: u8) -> Self {
        let sqrt_half = std::f64::consts::FRAC_1_SQRT_2;
        Tables {
            dc: table(256, |b| (b / 255.0 - 0.5) / COLOR_SCALE),
            scale: table(256, |b| (b / 16.0 - 10.0).exp()),
            v2_rotation: table(256, |b| b / 127.5 - 1.0),
            // 10-bit field: sign bit 9, then a 9-bit magnitude over 1/sqrt(2)
            smallest_three: table(1024, |f| if f >= 512.0 { -1.0 } else { 1.0 } * (f % 512.0) * sqrt_half / 511.0),
            // a power of two (or 0 for absurd headers), so positions are exact
            position_scale: 2.0_f64.powi(-i32::from(fractional_bits)) as f32,
        }
    }
}

/// Decode the attributes into `out`, whose `sh_coefficients` sets the SH degree kept.
pub fn decode(attributes: &Attributes<'_>, out: SplatsMut<'_>) -> Result<(), SizeError> {
    let n = out.count()?;
    let kept = 3 * (out.sh_coefficients - 1);
    check_len("positions", attributes.positions.len(), 9 * n)?;
    check_len("alphas", attributes.alphas.len(), n)?;
    check_len("colors", attributes.colors.len(), 3 * n)?;
    check_len("scales", attributes.scales.len(), 3 * n)?;
    check_len("rotations", attributes.rotations.len(), attributes.rotation_format.bytes() * n)?;
    check_len("sh", attributes.sh.len(), attributes.sh_bytes_per_splat * n)?;
    if attributes.sh_bytes_per_splat < kept {
        return Err(SizeError { name: "sh bytes per splat", expected: kept, got: attributes.sh_bytes_per_splat });
    }
    let tables = Tables::new(attributes.fractional_bits);
    out.for_each_block(BLOCK, |block| decode_block(attributes, &tables, block));
    Ok(())
}

fn decode_block(a: &Attributes<'_>, t: &Tables, block: Block<'_>) {
    let (first, size) = (block.start, block.opacities.len());
    // the block's bytes of an attribute stored `width` bytes per splat
    fn rows(data: &[u8], width: usize, first: usize, size: usize) -> &[u8] {
        &data[width * first..width * (first + size)]
    }
    let bytes = |data, width| rows(data, width, first, size);
    for (mean, fixed) in block.means.iter_mut().zip(bytes(a.positions, 9).chunks_exact(9)) {
        for (axis, value) in mean.iter_mut().enumerate() {
            let b = &fixed[3 * axis..3 * axis + 3];
            // 24-bit little-endian, sign-extended by shifting it to the top of an i32 and back
            let fixed = i32::from_le_bytes([0, b[0], b[1], b[2]]) >> 8;
            *value = fixed as f32 * t.position_scale;
        }
    }
    for (opacity, &b) in block.opacities.iter_mut().zip(bytes(a.alphas, 1)) {
        *opacity = f32::from(b) / 255.0;
    }
    for (scale, b) in block.scales.iter_mut().zip(bytes(a.scales, 3).chunks_exact(3)) {
        *scale = [0, 1, 2].map(|axis| t.scale[usize::from(b[axis])]);
    }
    let width = a.rotation_format.bytes();
    for (quat, b) in block.quats.iter_mut().zip(bytes(a.rotations, width).chunks_exact(width)) {
        *quat = match a.rotation_format {
            Rotations::XyzBytes => v2_rotation(t, b),
            Rotations::SmallestThree => {
                let packed = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                let field = |shift: u32| t.smallest_three[((packed >> shift) & 0x3FF) as usize];
                // SPZ orders components x, y, z, w
                smallest_three([field(20), field(10), field(0)], (packed >> 30) as usize, [3, 0, 1, 2])
            }
        };
    }
    let row = block.sh.len() / size.max(1);
    for (i, (sh, color)) in block.sh.chunks_exact_mut(row).zip(bytes(a.colors, 3).chunks_exact(3)).enumerate() {
        let (dc, rest) = sh.split_at_mut(3);
        for (value, &b) in dc.iter_mut().zip(color) {
            *value = t.dc[usize::from(b)];
        }
        let coefficients = &a.sh[a.sh_bytes_per_splat * (first + i)..][..rest.len()];
        for (value, &b) in rest.iter_mut().zip(coefficients) {
            // (b - 128) / 128: b ^ 0x80 read as i8 is b - 128, and 1/128 is exact
            *value = f32::from((b ^ 0x80) as i8) * (1.0 / 128.0);
        }
    }
}

/// Version 2: x, y, z bytes, w = sqrt(1 - |xyz|^2) >= 0; renormalised, as |xyz| may exceed 1.
fn v2_rotation(t: &Tables, bytes: &[u8]) -> [f32; 4] {
    let [x, y, z] = [0, 1, 2].map(|i| t.v2_rotation[usize::from(bytes[i])]);
    let squared = x * x + y * y + z * z;
    let mut q = [(1.0 - squared).max(0.0).sqrt(), x, y, z];
    if squared > 1.0 {
        let norm = squared.sqrt();
        q.iter_mut().for_each(|c| *c /= norm);
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    type Arrays = (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>);

    fn decode_one(payload: &[u8], rotations: Rotations, sh_bytes: usize, k: usize) -> Arrays {
        let (mut means, mut scales, mut quats, mut opacities, mut sh) =
            (vec![0.0; 3], vec![0.0; 3], vec![0.0; 4], vec![0.0; 1], vec![0.0; 3 * k]);
        let attributes = Attributes::split(payload, 1, rotations, sh_bytes, 12).unwrap_or_else(|e| unreachable!("{e}"));
        let out = SplatsMut {
            means: &mut means,
            scales: &mut scales,
            quats: &mut quats,
            opacities: &mut opacities,
            sh: &mut sh,
            sh_coefficients: k,
        };
        decode(&attributes, out).unwrap_or_else(|e| unreachable!("{e}"));
        (means, scales, quats, opacities, sh)
    }

    #[test]
    fn one_splat_written_byte_by_byte() {
        let mut payload = vec![0x00, 0x08, 0x00, 0x00, 0xF8, 0xFF, 0xFF, 0xFF, 0x7F]; // 0.5, -0.5, (2^23 - 1) / 2^12
        payload.push(51); // alpha 0.2
        payload.extend([0, 128, 255]); // colour
        payload.extend([160, 0, 255]); // log scales 0, -10, 255/16 - 10
        // largest is y (index 1 of x, y, z, w); x: sign bit and magnitude 511, z: 0, w: 256
        let word: u32 = (1 << 30) | (((1 << 9) | 511) << 20) | 256;
        payload.extend(word.to_le_bytes());
        payload.extend([0, 128, 255, 0, 128, 255, 0, 128, 255]); // degree 1
        let (means, scales, quats, opacities, sh) = decode_one(&payload, Rotations::SmallestThree, 9, 4);
        assert_eq!(means, [0.5, -0.5, 8_388_607.0 / 4096.0]);
        assert_eq!(opacities, [0.2]);
        let expected_scales = [1.0_f64, (-10.0_f64).exp(), (255.0_f64 / 16.0 - 10.0).exp()];
        assert!(scales.iter().zip(expected_scales).all(|(&s, e)| (f64::from(s) - e).abs() <= 1e-6 * e));
        let (x, w) = (-std::f64::consts::FRAC_1_SQRT_2, std::f64::consts::FRAC_1_SQRT_2 * 256.0 / 511.0);
        let y = (1.0 - x * x - w * w).sqrt();
        assert!(quats.iter().zip([w, x, y, 0.0]).all(|(&q, e)| (f64::from(q) - e).abs() < 1e-6));
        assert_eq!(&sh[..3], &[(-0.5 / 0.15) as f32, ((128.0 / 255.0 - 0.5) / 0.15) as f32, (0.5 / 0.15) as f32]);
        assert_eq!(&sh[3..], &[-1.0, 0.0, 127.0 / 128.0, -1.0, 0.0, 127.0 / 128.0, -1.0, 0.0, 127.0 / 128.0]);
    }

    #[test]
    fn version_2_rebuilds_w_and_degree_4_keeps_degree_3() {
        let mut payload = vec![0; 9];
        payload.extend([255, 128, 128, 128, 160, 160, 160]);
        payload.extend([255, 128, 0]); // |xyz| > 1: w = 0 and the rest rescaled
        payload.extend((0..72).map(|i| if i < 45 { 160 } else { 0 })); // degree 4: 24 coefficients
        let (_, _, quats, _, sh) = decode_one(&payload, Rotations::XyzBytes, 72, 16);
        let (x, y, z) = (1.0_f64, 128.0 / 127.5 - 1.0, -1.0);
        let norm = (x * x + y * y + z * z).sqrt();
        assert!(quats.iter().zip([0.0, x / norm, y / norm, z / norm]).all(|(&q, e)| (f64::from(q) - e).abs() < 1e-6));
        assert!(sh[3..].iter().all(|&v| v == 0.25)); // band 4 (the zero bytes) dropped
    }

    #[test]
    fn sizes_that_disagree_are_errors() {
        assert!(Attributes::split(&[0; 21], 1, Rotations::SmallestThree, 0, 12).is_err());
        let attributes =
            Attributes::split(&[0; 23], 1, Rotations::SmallestThree, 3, 12).unwrap_or_else(|e| unreachable!("{e}"));
        let (mut a, mut b, mut c, mut d, mut e) =
            (vec![0.0; 3], vec![0.0; 3], vec![0.0; 4], vec![0.0; 1], vec![0.0; 27]);
        let out = SplatsMut {
            means: &mut a,
            scales: &mut b,
            quats: &mut c,
            opacities: &mut d,
            sh: &mut e,
            sh_coefficients: 9,
        };
        assert_eq!(decode(&attributes, out).err().map(|e| e.name), Some("sh bytes per splat"));
    }
}
