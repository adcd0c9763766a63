//! Whole-buffer gzip inflation (libdeflate: about twice the speed of zlib's streaming inflate).
//!
//! The caller knows how many bytes the stream should hold and passes a buffer of that size, so
//! a stream that expands further (a gzip bomb, or a count that disagrees with the data) stops as
//! soon as the buffer is full.

use libdeflater::{DecompressionError, Decompressor};

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
    Decompressor::new().gzip_decompress(raw, out).map_err(|error| match error {
        DecompressionError::InsufficientSpace => GunzipError::TooLong(out.len()),
        DecompressionError::BadData => GunzipError::Corrupt,
    })
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
}
