//! Buffers kept from one render to the next (docs/rendering.md, "Buffers kept between renders").
//!
//! A full render writes 60 bytes of projection for every Gaussian and sorts 8 bytes of key (and
//! as many of scratch) for each. In fresh memory the system's page faults and page zeroing took a
//! quarter of the projection and a third of the sort at capture size. So these buffers are taken
//! from here when a render starts and given back when it ends, and the next render writes into
//! pages it already has. What is kept stays held, about 76 bytes per Gaussian of the largest
//! scene rendered, until [`release_kept_buffers`].

use std::sync::Mutex;

use crate::project::Splat2D;
use crate::tiles::TileRect;

/// One kept buffer: empty until a render gives one back.
pub(crate) struct Kept<T>(Mutex<Vec<T>>);

impl<T> Kept<T> {
    const fn new() -> Self {
        Self(Mutex::new(Vec::new()))
    }

    /// The kept buffer, contents and all (empty when none is kept, or while another render of
    /// this process holds it).
    pub(crate) fn take(&self) -> Vec<T> {
        self.0.try_lock().map(|mut kept| std::mem::take(&mut *kept)).unwrap_or_default()
    }

    /// Keeps `buffer` for the next render, unless a larger one is kept already. Never waits: a
    /// buffer that finds the lock taken is dropped (and a process forked while another thread held
    /// the lock cannot hang here).
    pub(crate) fn give_back(&self, buffer: Vec<T>) {
        if let Ok(mut kept) = self.0.try_lock()
            && buffer.capacity() > kept.capacity()
        {
            *kept = buffer;
        }
    }

    fn release(&self) {
        if let Ok(mut kept) = self.0.try_lock() {
            *kept = Vec::new();
        }
    }
}

pub(crate) static SPLATS: Kept<Splat2D> = Kept::new();
pub(crate) static RECTS: Kept<TileRect> = Kept::new();
pub(crate) static DEPTHS: Kept<f32> = Kept::new();
pub(crate) static SORT_KEYS: Kept<u64> = Kept::new();
pub(crate) static SORT_SCRATCH: Kept<u64> = Kept::new();

/// Frees the buffers renders keep for the next one (the next render allocates afresh).
pub fn release_kept_buffers() {
    SPLATS.release();
    RECTS.release();
    DEPTHS.release();
    SORT_KEYS.release();
    SORT_SCRATCH.release();
}

/// `buffer` (from [`Kept::take`]) holding `len` values, each zero bits where it had to grow: a
/// buffer too short is replaced by zeroed pages from the system, which its writers then touch in
/// parallel, rather than filled here on one thread. What it held before is left as it was.
pub(crate) fn with_len<T: bytemuck::Zeroable + Clone>(mut buffer: Vec<T>, len: usize) -> Vec<T> {
    if buffer.capacity() < len {
        return bytemuck::zeroed_vec(len);
    }
    buffer.resize(len, T::zeroed());
    buffer
}
