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
        let Some(layout) = Self::huge_layout(v.len()) else {
            return Self::small(v);
        };
        // SAFETY: the layout's size is at least one huge page, not zero.
        let raw = unsafe { alloc(layout) };
        let Some(ptr) = NonNull::new(raw as *mut T) else {
            return Self::small(v);
        };
        // Before the copy below first touches the pages, so that the faults map huge ones.
        advise_huge_pages(raw, layout.size());
        // SAFETY: the new allocation holds at least `v.len()` values, its alignment (2 MiB)
        // is a multiple of T's (checked above; both are powers of two), and it does not overlap `v`.
        unsafe { std::ptr::copy_nonoverlapping(v.as_ptr(), ptr.as_ptr(), v.len()) };
        PagedSlice { ptr, len: v.len(), owner: Owner::Huge(layout) }
    }

    /// The first `len` values of `values` (fewer if it ends sooner), written straight into
    /// the huge-page allocation: a large array built once costs one write and a few hundred
    /// page faults instead of a vector's faults and then a copy.
    pub fn from_iter_len(len: usize, values: impl Iterator<Item = T>) -> PagedSlice<T> {
        let Some(layout) = Self::huge_layout(len) else {
            return Self::small(values.take(len).collect());
        };
        // SAFETY: the layout's size is at least one huge page, not zero.
        let raw = unsafe { alloc(layout) };
        let Some(ptr) = NonNull::new(raw as *mut T) else {
            return Self::small(values.take(len).collect());
        };
        advise_huge_pages(raw, layout.size());
        let mut n = 0;
        for v in values.take(len) {
            // SAFETY: n < len, and the allocation holds `len` values of T, suitably aligned
            // (`huge_layout`). T is Copy: nothing is dropped by overwriting or by a panic of the
            // iterator (which leaks the allocation, nothing worse).
            unsafe { ptr.as_ptr().add(n).write(v) };
            n += 1;
        }
        // Only the first n values were written: the slice covers those.
        PagedSlice { ptr, len: n, owner: Owner::Huge(layout) }
    }

    /// The 2 MiB-aligned layout for `len` values, or None where they go in a vector.
    fn huge_layout(len: usize) -> Option<Layout> {
        let bytes = len.checked_mul(std::mem::size_of::<T>())?;
        if !HUGE_PAGES_ADVISABLE || bytes < HUGE_PAGE || std::mem::align_of::<T>() > HUGE_PAGE {
            return None;
        }
        Layout::from_size_align(bytes.next_multiple_of(HUGE_PAGE), HUGE_PAGE).ok()
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

    #[test]
    fn from_iter_len_same_values() {
        let n = 3 * HUGE_PAGE / 8 + 5;
        let val = |i: usize| (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let h = PagedSlice::from_iter_len(n, (0..n).map(val));
        assert_eq!(h.is_huge(), HUGE_PAGES_ADVISABLE);
        assert!(h.iter().copied().eq((0..n).map(val)));
        // A shorter iterator gives a shorter slice; a longer one is cut at `len`.
        let short = PagedSlice::from_iter_len(n, (0..n - 7).map(val));
        assert!(short.iter().copied().eq((0..n - 7).map(val)));
        let long = PagedSlice::from_iter_len(n, (0..2 * n).map(val));
        assert!(long.iter().copied().eq((0..n).map(val)));
        let small = PagedSlice::from_iter_len(10, (0..100).map(val));
        assert!(!small.is_huge());
        assert!(small.iter().copied().eq((0..10).map(val)));
    }
}
