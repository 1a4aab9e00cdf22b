//! A bound on what a third-party parser may allocate. dicom-rs reserves the length an element
//! declares before it reads the value; the length walk in `dicom/lenient.rs` checks every
//! length against the file first, but where dicom-rs and the walk disagree on where a
//! sequence ends (a corrupt file can make them), dicom-rs reads a "length" out of other bytes
//! and reserves gigabytes. While one file is parsed, [`GuardedAllocator`] refuses any single
//! allocation above a bound tied to the file's size, so that dicom-rs's `try_reserve` fails
//! into an ordinary error. It takes effect in a program that installs it as its global
//! allocator (the `voyage` binary, the fuzz targets, the DICOM tests); elsewhere [`capped`]
//! changes nothing.

use std::{
    alloc::{GlobalAlloc, Layout, System},
    cell::Cell,
};

thread_local! {
    /// The largest single allocation allowed on this thread now (usize::MAX: no bound).
    static CAP: Cell<usize> = const { Cell::new(usize::MAX) };
}

/// The system allocator, refusing on a thread inside [`capped`] any allocation larger than
/// the bound given there. For a program to install: `#[global_allocator] static A:
/// voyage_io::GuardedAllocator = voyage_io::GuardedAllocator;`.
pub struct GuardedAllocator;

fn allowed(size: usize) -> bool {
    CAP.try_with(|c| size <= c.get()).unwrap_or(true)
}

// SAFETY: every call is passed on to `System` unchanged, or refused with a null pointer,
// which the `GlobalAlloc` contract allows for any request.
unsafe impl GlobalAlloc for GuardedAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if !allowed(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: the caller's obligations for `alloc` are passed on as they are.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if !allowed(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: as for `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System` through this allocator, with `layout`.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if !allowed(new_size) {
            return std::ptr::null_mut();
        }
        // SAFETY: as for `dealloc`, and the caller's obligations for `realloc`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Runs `f` with single allocations on this thread bounded by `bytes` (where the program
/// installed [`GuardedAllocator`]); bounds nest, the tighter one holding.
pub(crate) fn capped<T>(bytes: usize, f: impl FnOnce() -> T) -> T {
    struct Restore(usize);
    impl Drop for Restore {
        fn drop(&mut self) {
            let _ = CAP.try_with(|c| c.set(self.0));
        }
    }
    let before = CAP.with(|c| c.replace(c.get().min(bytes)));
    let _restore = Restore(before);
    f()
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_bound_nests_and_is_lifted_afterwards() {
        super::capped(1000, || {
            assert!(super::allowed(1000) && !super::allowed(1001));
            super::capped(5000, || assert!(!super::allowed(1001)));
            super::capped(10, || assert!(!super::allowed(11)));
            assert!(super::allowed(1000));
        });
        assert!(super::allowed(usize::MAX));
    }
}
