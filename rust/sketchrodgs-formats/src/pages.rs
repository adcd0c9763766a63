//! Big buffers whose first touches cost less: inflating writes tens of megabytes of fresh
//! memory, and faulting it in 4 KiB pages was a large part of the time.

/// Ask the kernel to back the allocation of `buffer` (its whole capacity) with huge pages where
/// it can. Advice only: contents and behaviour are unchanged.
pub(crate) fn advise_huge_pages<T>(buffer: &Vec<T>) {
    advise(buffer.as_ptr() as usize, buffer.capacity() * size_of::<T>());
}

/// The same for the `bytes` from address `start`, which must lie in one live allocation of ours.
fn advise(start: usize, bytes: usize) {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let begin = start.next_multiple_of(HUGE);
        let end = (start + bytes) / HUGE * HUGE;
        if end > begin {
            // SAFETY: advice on whole pages inside a live allocation we own; it changes no
            // contents and no mapping.
            unsafe { libc::madvise(begin as *mut libc::c_void, end - begin, libc::MADV_HUGEPAGE) };
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (start, bytes);
}

/// Zeroed bytes in pages of their own, fresh from the kernel: only the pages written are ever
/// backed by memory. (A zeroed allocation that the heap serves from freed memory is cleared in
/// full, which for an output buffer of tens of megabytes costs more than the part inflated into
/// it.)
pub(crate) struct FreshBytes {
    #[cfg(unix)]
    map: std::ptr::NonNull<u8>,
    #[cfg(unix)]
    len: usize,
    #[cfg(not(unix))]
    bytes: Vec<u8>,
}

// SAFETY: the mapping is owned by this value alone, like a Vec's buffer.
unsafe impl Send for FreshBytes {}
unsafe impl Sync for FreshBytes {}

impl FreshBytes {
    /// `len` zero bytes; None if the kernel refuses the mapping.
    #[cfg(unix)]
    pub fn new(len: usize) -> Option<Self> {
        let len = len.max(1);
        // SAFETY: a new private anonymous mapping; no existing memory is touched.
        let map = unsafe {
            libc::mmap(std::ptr::null_mut(), len, libc::PROT_READ | libc::PROT_WRITE, libc::MAP_PRIVATE | libc::MAP_ANONYMOUS, -1, 0)
        };
        if map == libc::MAP_FAILED {
            return None;
        }
        advise(map as usize, len);
        Some(FreshBytes { map: std::ptr::NonNull::new(map.cast())?, len })
    }

    #[cfg(not(unix))]
    pub fn new(len: usize) -> Option<Self> {
        Some(FreshBytes { bytes: vec![0; len] })
    }
}

impl std::ops::Deref for FreshBytes {
    type Target = [u8];

    #[cfg(unix)]
    fn deref(&self) -> &[u8] {
        // SAFETY: `len` bytes mapped readable and writable (zero until written) while self lives.
        unsafe { std::slice::from_raw_parts(self.map.as_ptr(), self.len) }
    }

    #[cfg(not(unix))]
    fn deref(&self) -> &[u8] {
        &self.bytes
    }
}

impl std::ops::DerefMut for FreshBytes {
    #[cfg(unix)]
    fn deref_mut(&mut self) -> &mut [u8] {
        // SAFETY: as in `deref`, and `&mut self` makes this the only reference.
        unsafe { std::slice::from_raw_parts_mut(self.map.as_ptr(), self.len) }
    }

    #[cfg(not(unix))]
    fn deref_mut(&mut self) -> &mut [u8] {
        &mut self.bytes
    }
}

#[cfg(unix)]
impl Drop for FreshBytes {
    fn drop(&mut self) {
        // SAFETY: unmaps exactly the mapping made in `new`, which nothing refers to any more.
        unsafe { libc::munmap(self.map.as_ptr().cast(), self.len) };
    }
}
