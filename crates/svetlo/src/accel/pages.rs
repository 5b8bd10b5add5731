//! The accelerator's large read-only arrays (nodes, triangle blocks) on 2 MiB pages.
//!
//! An incoherent ray touches a few cache lines in each of many far-apart pages: with 4 KiB
//! pages nearly every node and leaf visit of a large scene also misses the TLB, and the page
//! walk itself waits on memory. On Linux, an array of at least one huge page is moved into a
//! 2 MiB-aligned allocation that is advised (`MADV_HUGEPAGE`) before it is first written,
//! so that the kernel backs it with huge pages where transparent huge pages are enabled
//! (`always` or `madvise`). Elsewhere, or if the advice fails, it is ordinary memory: only
//! the speed differs, never the content.

use std::alloc::{alloc, dealloc, Layout};
use std::ops::Deref;
use std::ptr::NonNull;

/// The huge page size of x86_64 and aarch64 (4 KiB granule) Linux.
const HUGE_PAGE: usize = 2 << 20;

/// A fixed slice of `T`, on huge pages when large enough (see the module's comment).
pub struct PagedSlice<T: Copy> {
    /// `len` values at `ptr`, in the allocation `owner` holds (a branch-free `deref`).
    ptr: NonNull<T>,
    len: usize,
    owner: Owner<T>,
}

enum Owner<T> {
    /// A small slice stays in its vector (whose heap buffer does not move with it).
    Vec(#[allow(dead_code)] Vec<T>),
    /// An allocation of this layout: 2 MiB-aligned, whole huge pages.
    Huge(Layout),
}

// SAFETY: the allocation is owned by the value alone and never written after construction:
// sharing or sending it is sharing or sending `[T]`.
unsafe impl<T: Copy + Send> Send for PagedSlice<T> {}
// SAFETY: as for `Send`.
unsafe impl<T: Copy + Sync> Sync for PagedSlice<T> {}

impl<T: Copy> PagedSlice<T> {
    pub fn new(v: Vec<T>) -> PagedSlice<T> {
        let bytes = std::mem::size_of_val(&v[..]);
        if !HUGE_PAGES_ADVISABLE || bytes < HUGE_PAGE || std::mem::align_of::<T>() > HUGE_PAGE {
            return Self::small(v);
        }
        let Ok(layout) = Layout::from_size_align(bytes.next_multiple_of(HUGE_PAGE), HUGE_PAGE) else {
            return Self::small(v);
        };
        // SAFETY: the layout's size is at least one huge page, not zero.
        let raw = unsafe { alloc(layout) };
        let Some(ptr) = NonNull::new(raw as *mut T) else {
            return Self::small(v);
        };
        // Before the copy below first touches the pages, so that the faults map huge ones.
        advise_huge_pages(raw, layout.size());
        // SAFETY: the new allocation holds `layout.size() >= bytes` bytes, its alignment (2 MiB)
        // is a multiple of T's (checked above; both are powers of two), and it does not overlap `v`.
        unsafe { std::ptr::copy_nonoverlapping(v.as_ptr(), ptr.as_ptr(), v.len()) };
        PagedSlice { ptr, len: v.len(), owner: Owner::Huge(layout) }
    }

    fn small(mut v: Vec<T>) -> PagedSlice<T> {
        // A vector's pointer is never null (dangling but aligned when empty).
        let ptr = NonNull::new(v.as_mut_ptr()).unwrap_or(NonNull::dangling());
        PagedSlice { ptr, len: v.len(), owner: Owner::Vec(v) }
    }

    /// Whether the values live in a huge-page-advised allocation (for the tests).
    #[cfg(test)]
    pub fn is_huge(&self) -> bool {
        matches!(self.owner, Owner::Huge(_))
    }
}

impl<T: Copy> Deref for PagedSlice<T> {
    type Target = [T];

    #[inline(always)]
    fn deref(&self) -> &[T] {
        // SAFETY: `ptr` holds `len` values, written before construction ended and owned by
        // `owner` until drop.
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> Clone for PagedSlice<T> {
    fn clone(&self) -> PagedSlice<T> {
        PagedSlice::new(self.to_vec())
    }
}

impl<T: Copy> Drop for PagedSlice<T> {
    fn drop(&mut self) {
        if let Owner::Huge(layout) = self.owner {
            // SAFETY: allocated in `new` with this layout, freed only here.
            unsafe { dealloc(self.ptr.as_ptr() as *mut u8, layout) };
        }
    }
}

const HUGE_PAGES_ADVISABLE: bool = cfg!(all(target_os = "linux", any(target_arch = "x86_64", target_arch = "aarch64")));

#[cfg(all(target_os = "linux", any(target_arch = "x86_64", target_arch = "aarch64")))]
fn advise_huge_pages(p: *mut u8, len: usize) {
    use std::ffi::{c_int, c_void};
    // libc's, which std links on Linux anyway.
    extern "C" {
        fn madvise(addr: *mut c_void, len: usize, advice: c_int) -> c_int;
    }
    /// The value of Linux's generic mman-common.h, used by x86_64 and aarch64.
    const MADV_HUGEPAGE: c_int = 14;
    // SAFETY: [p, p + len) is one whole allocation of ours, page-aligned; the advice changes
    // how it is backed, never its content. On failure (THP off, old kernel) the pages stay
    // small, which is only slower: the result is ignored.
    unsafe { madvise(p as *mut c_void, len, MADV_HUGEPAGE) };
}

#[cfg(not(all(target_os = "linux", any(target_arch = "x86_64", target_arch = "aarch64"))))]
fn advise_huge_pages(_: *mut u8, _: usize) {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_values_small_and_huge() {
        let small: Vec<u32> = (0..1000).collect();
        let s = PagedSlice::new(small.clone());
        assert!(!s.is_huge());
        assert_eq!(&s[..], &small[..]);
        // Three huge pages and a bit: rounded up to four.
        let big: Vec<u64> = (0..(3 * HUGE_PAGE / 8 + 5) as u64).map(|i| i.wrapping_mul(0x9e37_79b9_7f4a_7c15)).collect();
        let h = PagedSlice::new(big.clone());
        assert_eq!(h.is_huge(), HUGE_PAGES_ADVISABLE);
        assert_eq!(&h[..], &big[..]);
        let c = h.clone();
        drop(h);
        assert_eq!(&c[..], &big[..]);
        assert!(PagedSlice::<u8>::new(Vec::new()).is_empty());
    }
}
