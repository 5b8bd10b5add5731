//! How an untimed render's samples split into passes, and the fixed order in which the passes'
//! sums are added: a pairwise tree over the pass indices. Because the tree's shape depends on
//! nothing but the number of passes, any node of it (a range of passes) can be rendered apart,
//! on another thread or machine, and the nodes' sums combined into the very image a local
//! render makes, bit for bit (float addition is commutative but not associative: the tree
//! fixes the association).
//!
//! The tree over passes `[a, b)` splits at `a + p`, `p` the largest power of two below
//! `b - a`: perfect subtrees on the left, the rest on the right.

use crate::error::{Error, Result};
use std::ops::Range;

/// Pixel samples of one pass at most (without a time limit): bounds the work a cancel drops.
pub const PASS_PIXEL_SAMPLES: u64 = 1 << 22;

/// Passes an untimed render has at least (when it has that many samples per pixel): work
/// split over processes goes by whole passes, so a render of few samples must still have
/// passes of about equal size to share out.
pub const MIN_PASSES: u32 = 8;

/// Samples per pixel of the next pass after one of `last`, in a render of `spp` over `pixels`.
/// Passes are summed into the film by the pass tree, so their sizes fix the float summation
/// order: without a time limit they double (1, 2, 4, ...) up to the least of 64, about
/// `PASS_PIXEL_SAMPLES` per pass and `spp / MIN_PASSES`, whatever the timing, which keeps the
/// image independent of the machine's speed and the thread count. With a time limit
/// (`(limit, elapsed, spp_done)` in seconds) they aim at half-second passes that end at it.
pub fn next_pass_spp(last: u32, spp: u32, pixels: u64, timed: Option<(f64, f64, u32)>) -> u32 {
    match timed {
        None => (last.saturating_mul(2)).min(untimed_pass_cap(spp, pixels)),
        Some((limit, elapsed, done)) => {
            let per_spp = elapsed / done.max(1) as f64;
            if per_spp > 0.0 {
                ((0.5 / per_spp) as u32).clamp(1, 64).min((((limit - elapsed) / per_spp) as u32).max(1))
            } else {
                64
            }
        }
    }
}

/// The largest pass of an untimed render of `spp` over `pixels`.
fn untimed_pass_cap(spp: u32, pixels: u64) -> u32 {
    ((PASS_PIXEL_SAMPLES / pixels.max(1)).clamp(1, 64) as u32).min((spp / MIN_PASSES).max(1))
}

/// The passes of an untimed render of `spp` samples per pixel over `pixels` pixels: each
/// pass's first sample index and sample count, in order.
pub fn pass_plan(spp: u32, pixels: u64) -> Vec<(u32, u32)> {
    let mut plan = Vec::new();
    let (mut done, mut size) = (0u32, 1u32);
    while done < spp {
        let n = size.min(spp - done);
        plan.push((done, n));
        done += n;
        size = next_pass_spp(size, spp, pixels, None);
    }
    plan
}

/// Where the tree splits the passes `[a, b)` (`b - a >= 2`).
pub fn split(a: u32, b: u32) -> u32 {
    let n = b - a;
    debug_assert!(n >= 2);
    a + (1u32 << (31 - (n - 1).leading_zeros()))
}

/// Whether `range` is a node of the tree over `0..passes`.
pub fn is_node(range: &Range<u32>, passes: u32) -> bool {
    let (mut a, mut b) = (0, passes);
    if range.start >= range.end || range.end > passes {
        return false;
    }
    loop {
        if (a, b) == (range.start, range.end) {
            return true;
        }
        if b - a < 2 {
            return false;
        }
        let m = split(a, b);
        if range.end <= m {
            b = m;
        } else if range.start >= m {
            a = m;
        } else {
            return false;
        }
    }
}

/// At most `chunks` nodes of the tree over the passes of `plan` that partition it, in pass
/// order: the node with the most samples is split until there are `chunks` (or only single
/// passes are left), so the tasks carry about equal work.
pub fn chunk_nodes(plan: &[(u32, u32)], chunks: usize) -> Vec<Range<u32>> {
    let samples = |r: &Range<u32>| -> u64 { plan[r.start as usize..r.end as usize].iter().map(|p| p.1 as u64).sum() };
    if plan.is_empty() {
        return Vec::new();
    }
    let mut nodes: Vec<Range<u32>> = Vec::with_capacity(chunks.max(1));
    nodes.push(0..plan.len() as u32);
    while nodes.len() < chunks.max(1) {
        // The largest splittable node; the first of equals, for a deterministic plan.
        let Some((i, _)) = nodes.iter().enumerate().filter(|(_, r)| r.end - r.start >= 2).max_by(|x, y| samples(x.1).cmp(&samples(y.1)).then(y.0.cmp(&x.0)))
        else {
            break;
        };
        let r = nodes[i].clone();
        let m = split(r.start, r.end);
        nodes.splice(i..=i, [r.start..m, m..r.end]);
    }
    nodes
}

/// Pairwise sums in the tree's order, fed one pass at a time: a binary counter of perfect
/// subtrees, folded from the right at the end (the tree's ragged right spine).
pub struct TreeSum<T> {
    stack: Vec<(u32, T)>,
}

impl<T> Default for TreeSum<T> {
    fn default() -> Self {
        TreeSum { stack: Vec::new() }
    }
}

impl<T> TreeSum<T> {
    /// Add the next pass's sum; `add(left, right)` adds `right` into `left`.
    pub fn push(&mut self, value: T, add: impl Fn(&mut T, T)) {
        self.stack.push((1, value));
        while self.stack.len() >= 2 && self.stack[self.stack.len() - 1].0 == self.stack[self.stack.len() - 2].0 {
            let (n, right) = self.stack.pop().expect("two entries");
            let left = self.stack.last_mut().expect("two entries");
            add(&mut left.1, right);
            left.0 += n;
        }
    }

    /// [`Self::push`] adding by reference, keeping the sums it folded in in `spare` (cleared,
    /// they hold later passes without new allocations: fresh pages cost a fault each). There
    /// are never more of them than levels of the tree.
    pub fn push_recycling(&mut self, value: T, add: impl Fn(&mut T, &T), spare: &mut Vec<T>) {
        self.stack.push((1, value));
        while self.stack.len() >= 2 && self.stack[self.stack.len() - 1].0 == self.stack[self.stack.len() - 2].0 {
            let (n, right) = self.stack.pop().expect("two entries");
            let left = self.stack.last_mut().expect("two entries");
            add(&mut left.1, &right);
            left.0 += n;
            spare.push(right);
        }
    }

    /// The sum of every pass pushed (`None` when none was).
    pub fn finish(mut self, add: impl Fn(&mut T, T)) -> Option<T> {
        let (_, mut acc) = self.stack.pop()?;
        while let Some((_, mut left)) = self.stack.pop() {
            add(&mut left, acc);
            acc = left;
        }
        Some(acc)
    }

    /// The sum so far, without consuming (for observers of a render in progress): a copy of
    /// the newest subtree's sum with the older ones added into it by reference, so only one
    /// sum is copied. `add(acc, older)` must be commutative per element (float additions are),
    /// so the result has the bits [`Self::finish`] would give.
    pub fn peek(&self, add: impl Fn(&mut T, &T)) -> Option<T>
    where
        T: Clone,
    {
        let ((_, newest), older) = self.stack.split_last()?;
        let mut acc = newest.clone();
        for (_, left) in older.iter().rev() {
            add(&mut acc, left);
        }
        Some(acc)
    }
}

/// Combine node sums that partition the tree over `0..passes` in the tree's order.
/// `nodes` holds (range, sum); every range must be a node and each pass covered once.
pub fn combine<T>(mut nodes: Vec<(Range<u32>, T)>, passes: u32, add: &impl Fn(&mut T, T)) -> Result<T> {
    nodes.sort_by_key(|n| n.0.start);
    let mut next = 0;
    for (r, _) in &nodes {
        if r.start != next || !is_node(r, passes) {
            return Err(Error::Invalid(format!(
                "partial films must partition the {passes} passes into nodes of the pass tree: got passes {}..{} after {next}",
                r.start, r.end
            )));
        }
        next = r.end;
    }
    if next != passes {
        return Err(Error::Invalid(format!("partial films cover passes 0..{next} of 0..{passes}")));
    }
    let mut it = nodes.into_iter().peekable();
    let out = combine_range(0..passes, &mut it, add);
    Ok(out)
}

fn combine_range<T, I: Iterator<Item = (Range<u32>, T)>>(r: Range<u32>, it: &mut std::iter::Peekable<I>, add: &impl Fn(&mut T, T)) -> T {
    if it.peek().is_some_and(|(n, _)| *n == r) {
        return it.next().expect("peeked").1;
    }
    let m = split(r.start, r.end);
    let mut left = combine_range(r.start..m, it, add);
    let right = combine_range(m..r.end, it, add);
    add(&mut left, right);
    left
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sums as strings of the tree's bracketing, to compare orders exactly.
    fn bracket(l: &mut String, r: String) {
        *l = format!("({l}+{r})");
    }

    fn recursive(a: u32, b: u32) -> String {
        if b - a == 1 {
            return a.to_string();
        }
        let m = split(a, b);
        format!("({}+{})", recursive(a, m), recursive(m, b))
    }

    #[test]
    fn the_counter_sums_in_the_trees_order() {
        for n in 1..40u32 {
            let mut t = TreeSum::default();
            for i in 0..n {
                t.push(i.to_string(), bracket);
            }
            assert_eq!(t.finish(bracket).unwrap(), recursive(0, n), "{n} passes");
        }
    }

    /// Recycling keeps the tree's order and hands back each sum folded in, never more at a
    /// time than the tree has levels (a render reusing them holds no extra memory).
    #[test]
    fn recycling_sums_in_the_trees_order() {
        let add = |l: &mut String, r: &String| *l = format!("({l}+{r})");
        for n in 1..40u32 {
            let mut t = TreeSum::default();
            let (mut spare, mut folded) = (Vec::new(), 0);
            for i in 0..n {
                let before = spare.len();
                t.push_recycling(i.to_string(), add, &mut spare);
                folded += spare.len() - before;
                assert!(spare.len() <= 32 - n.leading_zeros() as usize, "{n} passes: {} spares", spare.len());
                spare.clear();
            }
            assert_eq!(folded, n as usize - t.stack.len(), "{n} passes: every sum folded in comes back");
            assert_eq!(t.finish(bracket).unwrap(), recursive(0, n), "{n} passes");
        }
    }

    /// A peek in the middle of a render has the bits the render would finish with there,
    /// though it adds the subtrees in the other order (float addition commutes).
    #[test]
    fn a_peek_has_the_bits_of_finishing_there() {
        let add = |a: &mut Vec<f32>, b: &Vec<f32>| a.iter_mut().zip(b).for_each(|(x, y)| *x += *y);
        let mut rng = crate::sampling::rng::Pcg32::new(7, 1);
        let passes: Vec<Vec<f32>> = (0..37).map(|_| (0..16).map(|_| rng.next_f32() * 1e3 - 1.0).collect()).collect();
        let mut t = TreeSum::default();
        for (i, p) in passes.iter().enumerate() {
            t.push(p.clone(), |a, b| add(a, &b));
            let mut whole = TreeSum::default();
            for q in &passes[..=i] {
                whole.push(q.clone(), |a, b| add(a, &b));
            }
            let finished = whole.finish(|a, b| add(a, &b)).unwrap();
            let peeked = t.peek(add).unwrap();
            assert_eq!(
                peeked.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                finished.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                "after {} passes",
                i + 1
            );
        }
    }

    #[test]
    fn any_partition_into_nodes_combines_to_the_whole_trees_order() {
        for n in 1..30u32 {
            for chunks in 1..12 {
                let plan: Vec<(u32, u32)> = (0..n).map(|i| (i, 1)).collect();
                let nodes = chunk_nodes(&plan, chunks);
                assert_eq!(nodes.len(), chunks.min(n as usize), "{n} passes, {chunks} chunks");
                let sums: Vec<(Range<u32>, String)> = nodes.iter().map(|r| (r.clone(), recursive(r.start, r.end))).collect();
                // Each node alone summed with the counter, as a worker does.
                for (r, s) in &sums {
                    let mut t = TreeSum::default();
                    for i in r.clone() {
                        t.push(i.to_string(), bracket);
                    }
                    assert_eq!(&t.finish(bracket).unwrap(), s);
                }
                assert_eq!(combine(sums, n, &bracket).unwrap(), recursive(0, n));
            }
        }
    }

    #[test]
    fn bad_partitions_are_refused() {
        let one = |r: Range<u32>| (r.clone(), String::new());
        assert!(combine(vec![one(0..2)], 3, &bracket).is_err(), "a pass missing");
        assert!(combine(vec![one(0..1), one(1..3)], 3, &bracket).is_err(), "1..3 is no node of 0..3");
        assert!(combine(vec![one(0..2), one(0..2), one(2..3)], 3, &bracket).is_err(), "a node twice");
        assert!(combine(vec![one(0..2), one(2..3)], 3, &bracket).is_ok());
    }

    #[test]
    fn the_plan_follows_the_pass_sizes() {
        assert_eq!(pass_plan(10, 100), (0..10).map(|i| (i, 1)).collect::<Vec<_>>());
        assert_eq!(pass_plan(40, 100), [(0, 1), (1, 2), (3, 4), (7, 5), (12, 5), (17, 5), (22, 5), (27, 5), (32, 5), (37, 3)]);
        let big = pass_plan(1000, 512 * 512);
        assert!(big.iter().skip(4).all(|p| p.1 == 16 || p.0 + p.1 == 1000));
        // A render of few samples still has passes to share out, of equal size.
        for spp in [1, 2, 5, 8, 13, 15] {
            let plan = pass_plan(spp, 512 * 512);
            assert_eq!(plan.len(), spp as usize, "{spp} spp");
            assert!(plan.iter().all(|p| p.1 == 1));
        }
        for spp in 16..600 {
            assert!(pass_plan(spp, 256 * 256).len() >= MIN_PASSES as usize, "{spp} spp");
        }
        assert_eq!(big.iter().map(|p| p.1).sum::<u32>(), 1000);
        // Chunks carry similar sample counts.
        let plan = pass_plan(4096, 64 * 64);
        let nodes = chunk_nodes(&plan, 8);
        let spp: Vec<u32> = nodes.iter().map(|r| plan[r.start as usize..r.end as usize].iter().map(|p| p.1).sum()).collect();
        assert_eq!(spp.iter().sum::<u32>(), 4096);
        assert!(spp.iter().all(|&s| (256..=1024).contains(&s)), "{spp:?}");
    }
}
