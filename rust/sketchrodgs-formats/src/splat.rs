//! antimatter15 `.splat`: headerless 32-byte records of position (3 x f32), linear scale
//! (3 x f32), RGBA (4 x u8, alpha the opacity) and rotation (4 x u8 holding 128 + 128 q, w first).

use crate::{BLOCK, Block, SH_C0, SplatsMut, check_len};

/// Bytes per record.
pub const RECORD: usize = 32;

/// Why records could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SplatError {
    #[error(transparent)]
    Size(#[from] crate::SizeError),
    #[error("rotation: zero quaternion in record {0}")]
    ZeroQuaternion(usize),
}

/// Decode `records` (32 bytes each) into `out`, whose SH must hold the DC term only. Rotations
/// are renormalised; a record whose rotation bytes are all 128 (no rotation at all) is an error.
/// Positions and scales are copied as stored: the scene's validation judges them.
pub fn decode(records: &[u8], out: SplatsMut<'_>) -> Result<(), SplatError> {
    let n = out.count()?;
    check_len("records", records.len(), RECORD * n)?;
    check_len("sh coefficients per channel", out.sh_coefficients, 1)?;
    let zero = std::sync::Mutex::new(None::<usize>);
    out.for_each_block(BLOCK, |block| {
        if let Some(row) = decode_block(records, block) {
            // keep the first bad record over all blocks
            if let Ok(mut first) = zero.lock() {
                *first = Some(first.map_or(row, |r: usize| r.min(row)));
            }
        }
    });
    match zero.into_inner().ok().flatten() {
        Some(row) => Err(SplatError::ZeroQuaternion(row)),
        None => Ok(()),
    }
}

/// Decode one block; the first record with a zero quaternion, if any.
fn decode_block(records: &[u8], block: Block<'_>) -> Option<usize> {
    let size = block.opacities.len();
    let rows = records[RECORD * block.start..RECORD * (block.start + size)].chunks_exact(RECORD);
    let f32_at = |r: &[u8], at: usize| f32::from_le_bytes([r[at], r[at + 1], r[at + 2], r[at + 3]]);
    let mut zero = None;
    for (i, r) in rows.enumerate() {
        block.means[i] = [f32_at(r, 0), f32_at(r, 4), f32_at(r, 8)];
        block.scales[i] = [f32_at(r, 12), f32_at(r, 16), f32_at(r, 20)];
        // DC term of colour c = u8 / 255: (c - 0.5) / SH_C0, in f32 as the reference loaders do
        for (channel, value) in block.sh[3 * i..3 * i + 3].iter_mut().enumerate() {
            *value = (f32::from(r[24 + channel]) / 255.0 - 0.5) / SH_C0 as f32;
        }
        block.opacities[i] = f32::from(r[27]) / 255.0;
        // q = (u8 - 128) / 128, normalised; the 1/128 cancels in the normalisation
        let q = [0, 1, 2, 3].map(|c| f32::from(r[28 + c]) - 128.0);
        let squared = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
        if squared == 0.0 {
            zero = zero.or(Some(block.start + i));
        }
        let scale = 1.0 / squared.sqrt();
        block.quats[i] = q.map(|c| c * scale);
    }
    zero
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(position: [f32; 3], scale: [f32; 3], rgba: [u8; 4], rotation: [u8; 4]) -> Vec<u8> {
        let mut r: Vec<u8> = position.iter().chain(&scale).flat_map(|v| v.to_le_bytes()).collect();
        r.extend(rgba);
        r.extend(rotation);
        r
    }

    #[test]
    fn records_decode_and_zero_rotations_are_named() {
        let mut records = record([1.0, -2.0, 3.5], [0.1, 0.2, 0.3], [255, 0, 128, 51], [255, 128, 128, 128]);
        records.extend(record([0.0; 3], [1.0; 3], [0; 4], [128, 128, 128, 128]));
        let (mut means, mut scales, mut quats, mut opacities, mut sh) =
            (vec![0.0; 6], vec![0.0; 6], vec![0.0; 8], vec![0.0; 2], vec![0.0; 6]);
        let out = SplatsMut {
            means: &mut means,
            scales: &mut scales,
            quats: &mut quats,
            opacities: &mut opacities,
            sh: &mut sh,
            sh_coefficients: 1,
        };
        assert_eq!(decode(&records, out), Err(SplatError::ZeroQuaternion(1)));
        assert_eq!(&means[..3], &[1.0, -2.0, 3.5]);
        assert_eq!(&scales[..3], &[0.1, 0.2, 0.3]);
        assert_eq!(&quats[..4], &[1.0, 0.0, 0.0, 0.0]);
        assert_eq!(opacities[0], 0.2);
        assert_eq!(sh[1], (0.0 - 0.5) / SH_C0 as f32);
    }
}
