//! Allocator tuning for the per-window hot path. Interface messages of up to a few MB are
//! allocated and freed every window (encode buffers, decoded arrays). glibc serves allocations
//! above its mmap threshold (128 kB at start) with fresh pages from the kernel, so each such
//! message pays a page fault per 4 kB (measured in the transport bench: ~380 µs to encode the
//! ~1 MB of a 10k-node round trip, 3 µs for 72 kB). Raising the mmap threshold keeps buffers up
//! to 16 MB in the heap, where freed pages are reused; the trim threshold keeps up to 64 MB of
//! freed heap instead of returning it to the kernel after every window.

/// Applies the tuning (glibc on Linux; elsewhere nothing). Call once at the start of `main`.
pub fn keep_message_buffers() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; called before other threads allocate
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 16 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 64 << 20);
    }
}
