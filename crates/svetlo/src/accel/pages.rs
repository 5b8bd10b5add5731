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
use std::ops::{Deref, DerefMut};
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

/// Room for `cap` values of `T` on huge pages: a 2 MiB-aligned allocation of whole huge pages,
/// advised before anything touches it, so that its first writes fault in huge pages. `None`
/// where the room would be under one huge page, huge pages are not advisable here, or the
/// allocation fails: the caller keeps ordinary memory then.
fn alloc_huge<T>(cap: usize) -> Option<(NonNull<T>, Layout)> {
    let bytes = cap.checked_mul(std::mem::size_of::<T>())?;
    if !HUGE_PAGES_ADVISABLE || bytes < HUGE_PAGE || std::mem::align_of::<T>() > HUGE_PAGE {
        return None;
    }
    let layout = Layout::from_size_align(bytes.next_multiple_of(HUGE_PAGE), HUGE_PAGE).ok()?;
    // SAFETY: the layout's size is at least one huge page, not zero.
    let raw = unsafe { alloc(layout) };
    let ptr = NonNull::new(raw as *mut T)?;
    advise_huge_pages(raw, layout.size());
    Some((ptr, layout))
}

impl<T: Copy> PagedSlice<T> {
    pub fn new(v: Vec<T>) -> PagedSlice<T> {
        let Some((ptr, layout)) = alloc_huge::<T>(v.len()) else {
            return Self::small(v);
        };
        // SAFETY: the new allocation holds at least `v.len()` values of T, its alignment (2 MiB)
        // is a multiple of T's (both are powers of two, `alloc_huge` checked the order), and it
        // does not overlap `v`.
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

impl<T: Copy + std::fmt::Debug> std::fmt::Debug for PagedSlice<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        (**self).fmt(f)
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

/// A growable array that lives where [`PagedSlice::new`] would move it: written in place on
/// huge pages when its capacity is large enough, so that a large array is neither faulted in
/// on small pages first nor copied once full (the build's arrays of tens of megabytes: their
/// page faults were a fifth of a 1M-triangle build).
pub struct PagedVec<T: Copy> {
    /// The first `len` of `cap` values at `ptr`, in the allocation `owner` holds.
    ptr: NonNull<T>,
    len: usize,
    cap: usize,
    owner: Owner<T>,
}

// SAFETY: the allocation is owned by the value alone, as a `Vec<T>`'s is.
unsafe impl<T: Copy + Send> Send for PagedVec<T> {}
// SAFETY: as for `Send`: `&PagedVec` gives `&[T]` only.
unsafe impl<T: Copy + Sync> Sync for PagedVec<T> {}

impl<T: Copy> PagedVec<T> {
    pub fn with_capacity(cap: usize) -> PagedVec<T> {
        match alloc_huge::<T>(cap) {
            Some((ptr, layout)) => PagedVec { ptr, len: 0, cap: layout.size() / std::mem::size_of::<T>().max(1), owner: Owner::Huge(layout) },
            None => Self::from_vec(Vec::with_capacity(cap)),
        }
    }

    fn from_vec(mut v: Vec<T>) -> PagedVec<T> {
        let ptr = NonNull::new(v.as_mut_ptr()).unwrap_or(NonNull::dangling());
        PagedVec { ptr, len: v.len(), cap: v.capacity(), owner: Owner::Vec(v) }
    }

    #[inline]
    pub fn push(&mut self, x: T) {
        if self.len == self.cap {
            self.grow();
        }
        // SAFETY: len < cap, so the slot lies inside the allocation. A vector owner's length
        // is set below as well, so that it stays the owner of what is written.
        unsafe { self.ptr.as_ptr().add(self.len).write(x) };
        self.len += 1;
        if let Owner::Vec(v) = &mut self.owner {
            // SAFETY: the first `len` values are written, `len <= capacity`.
            unsafe { v.set_len(self.len) };
        }
    }

    /// The room for `capacity()` values, to be written out of order (see `set_len`).
    pub fn as_mut_ptr(&mut self) -> *mut T {
        self.ptr.as_ptr()
    }

    pub fn capacity(&self) -> usize {
        self.cap
    }

    /// # Safety
    /// `len <= capacity()`, and the first `len` values were written (through `as_mut_ptr`).
    pub unsafe fn set_len(&mut self, len: usize) {
        debug_assert!(len <= self.cap);
        self.len = len;
        if let Owner::Vec(v) = &mut self.owner {
            // SAFETY: as the caller promised.
            unsafe { v.set_len(len) };
        }
    }

    /// Appends `count` values, `f(i)` the i-th of them, made on rayon's threads: each thread
    /// writes (and faults in) its own runs of the array.
    pub fn extend_par(&mut self, count: usize, f: impl Fn(usize) -> T + Sync)
    where
        T: Send,
    {
        self.extend_par_reduce(count, f, || (), |(), _| (), |(), ()| ());
    }

    /// [`extend_par`](Self::extend_par) that also folds the values as they are made (each
    /// run's from `identity()`), the runs' results combined by `reduce` in no fixed order: one
    /// pass over the values where a second would read them back from memory.
    pub fn extend_par_reduce<A: Send>(
        &mut self,
        count: usize,
        f: impl Fn(usize) -> T + Sync,
        identity: impl Fn() -> A + Sync + Send,
        fold: impl Fn(A, &T) -> A + Sync,
        reduce: impl Fn(A, A) -> A + Sync + Send,
    ) -> A
    where
        T: Send,
    {
        use rayon::prelude::*;
        use std::mem::MaybeUninit;
        /// Values per task: a few pages of large values, few tasks.
        const RUN: usize = 1024;
        let need = self.len.checked_add(count).expect("capacity overflow");
        if need > self.cap {
            self.grow_to(need);
        }
        // SAFETY: `len + count <= cap`: the spare room lies inside the allocation, unaliased
        // (`&mut self`), and is seen as uninitialized values.
        let spare = unsafe { std::slice::from_raw_parts_mut(self.ptr.as_ptr().add(self.len) as *mut MaybeUninit<T>, count) };
        let acc = spare
            .par_chunks_mut(RUN)
            .enumerate()
            .map(|(run, slots)| {
                let mut acc = identity();
                for (j, slot) in slots.iter_mut().enumerate() {
                    acc = fold(acc, slot.write(f(run * RUN + j)));
                }
                acc
            })
            .reduce(&identity, reduce);
        // SAFETY: the first `need` values are written, `need <= cap`.
        unsafe { self.set_len(need) };
        acc
    }

    /// Out of line: the capacities are chosen so that this is rare.
    #[cold]
    #[inline(never)]
    fn grow(&mut self) {
        self.grow_to((2 * self.cap).max(8));
    }

    /// Moves the values into an allocation for at least `cap` values (more than `len`).
    fn grow_to(&mut self, cap: usize) {
        let mut bigger = PagedVec::with_capacity(cap);
        // SAFETY: the new allocation holds more than `len` values and does not overlap ours.
        unsafe { std::ptr::copy_nonoverlapping(self.ptr.as_ptr(), bigger.ptr.as_ptr(), self.len) };
        bigger.len = self.len;
        if let Owner::Vec(v) = &mut bigger.owner {
            // SAFETY: the first `len` values were just written.
            unsafe { v.set_len(bigger.len) };
        }
        *self = bigger;
    }

    /// The values, frozen (on huge pages if large enough, moved there if not yet on them).
    pub fn into_slice(self) -> PagedSlice<T> {
        let me = std::mem::ManuallyDrop::new(self);
        // SAFETY: `me` is never used or dropped again: its owner moves into the result.
        match unsafe { std::ptr::read(&me.owner) } {
            Owner::Vec(v) => PagedSlice::new(v),
            Owner::Huge(layout) => PagedSlice { ptr: me.ptr, len: me.len, owner: Owner::Huge(layout) },
        }
    }
}

impl<T: Copy> Deref for PagedVec<T> {
    type Target = [T];

    #[inline(always)]
    fn deref(&self) -> &[T] {
        // SAFETY: the first `len` values at `ptr` are written (by `push`), owned by `owner`.
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> DerefMut for PagedVec<T> {
    #[inline(always)]
    fn deref_mut(&mut self) -> &mut [T] {
        // SAFETY: as in `deref`, and `&mut self` makes the access unique.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> Drop for PagedVec<T> {
    fn drop(&mut self) {
        if let Owner::Huge(layout) = self.owner {
            // SAFETY: allocated in `alloc_huge` with this layout, freed only here (or owned by
            // the PagedSlice of `into_slice`, which skips this drop).
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
    fn paged_vec_keeps_what_is_pushed() {
        // Small, huge from the start, and grown past its capacity (small to huge, huge to huge).
        let n = 3 * HUGE_PAGE / 8 + 5;
        let value = |i: usize| (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        for cap in [0, 1000, n, 2 * HUGE_PAGE / 8 - 3] {
            let mut v = PagedVec::with_capacity(cap);
            for i in 0..n {
                v.push(value(i));
            }
            v[7] = 7;
            let expect: Vec<u64> = (0..n).map(|i| if i == 7 { 7 } else { value(i) }).collect();
            assert_eq!(&v[..], &expect[..]);
            let s = v.into_slice();
            assert_eq!(s.is_huge(), HUGE_PAGES_ADVISABLE);
            assert_eq!(&s[..], &expect[..]);
        }
        // Extended in parallel: in its room, and past it (small to huge).
        for cap in [n, 10] {
            let mut v = PagedVec::with_capacity(cap);
            v.push(value(0));
            v.extend_par(n - 1, |i| value(i + 1));
            let expect: Vec<u64> = (0..n).map(value).collect();
            assert_eq!(&v[..], &expect[..]);
        }
        // Folded as they are made: every value once (a sum and a count, in any order).
        let mut v = PagedVec::with_capacity(5);
        let (sum, count) = v.extend_par_reduce(n, value, || (0u64, 0usize), |(s, c), x| (s.wrapping_add(*x), c + 1), |a, b| (a.0.wrapping_add(b.0), a.1 + b.1));
        let expect: Vec<u64> = (0..n).map(value).collect();
        assert_eq!(&v[..], &expect[..]);
        assert_eq!((sum, count), (expect.iter().fold(0u64, |s, x| s.wrapping_add(*x)), n));
        let mut small = PagedVec::with_capacity(4);
        small.push(1u32);
        let s = small.into_slice();
        assert!(!s.is_huge());
        assert_eq!(&s[..], &[1]);
    }
}
