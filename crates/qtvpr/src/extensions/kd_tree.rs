//! A static k-d tree for the radius queries of [`crate::extensions::ground_truth::within_radius`].
//!
//! Why not a crate: `kiddo` 6 needs Rust 1.89 (this project supports 1.88) and a large
//! dependency tree; in `kiddo` 5 the mutable tree panics when more than a bucket's worth
//! of points share a coordinate (the GPS fixes of a robot standing still) and its within
//! queries test `distance < radius` (exclusive), and the immutable tree has an open
//! report of wrong indices from within queries. Ground truth must be exact, so the index
//! here is small enough to check by eye, and it is tested against brute force.
//!
//! # Exactness
//! The tree only prunes; the decision `d² <= r²` is made per point with the same
//! arithmetic as NumPy's `((a - b)**2).sum(-1) <= r*r` (differences, squares, then a
//! left-to-right sum, all in `f64`). Pruning is exact too, not merely conservative up to
//! rounding: a node is skipped when the squared distance from the query to its bounding
//! box, computed the same way, exceeds `r²`. Rounding is monotone, so for every point
//! of the box each computed per-axis gap is at most the computed per-axis difference,
//! and the computed box distance is at most the computed point distance. A point with
//! `d² <= r²` is therefore never pruned, duplicates and points on split planes included.

/// Points per leaf.
const LEAF: usize = 16;

/// A node of the tree: the bounding box of `points[start..end]`, and its children.
struct Node<const K: usize> {
    lo: [f64; K],
    hi: [f64; K],
    start: usize,
    end: usize,
    /// Indices of the two children in `nodes`, or `None` for a leaf.
    children: Option<(usize, usize)>,
}

/// A k-d tree over K-dimensional points, balanced by median splits on the axis of
/// largest extent (trajectories are long and thin, so this beats cycling the axes).
pub(crate) struct KdTree<const K: usize> {
    /// The points, reordered so that every node covers a contiguous range.
    points: Vec<[f64; K]>,
    /// `index[t]` is the caller's index of `points[t]`.
    index: Vec<usize>,
    nodes: Vec<Node<K>>,
}

impl<const K: usize> KdTree<K> {
    /// Build the tree; `points` must be non-empty and finite.
    pub(crate) fn new(points: Vec<[f64; K]>) -> Self {
        let mut order: Vec<(usize, [f64; K])> = points.into_iter().enumerate().collect();
        let mut nodes = Vec::new();
        let n = order.len();
        build(&mut order, 0, n, &mut nodes);
        let (index, points) = order.into_iter().unzip();
        Self { points, index, nodes }
    }

    /// Call `found(i)` for the caller's index `i` of every point `p` whose squared
    /// distance to `q` is `<= r2` (computed as described in the module docs), in no
    /// particular order.
    pub(crate) fn within(&self, q: &[f64; K], r2: f64, found: &mut impl FnMut(usize)) {
        self.visit(0, q, r2, found);
    }

    fn visit(&self, node: usize, q: &[f64; K], r2: f64, found: &mut impl FnMut(usize)) {
        let n = &self.nodes[node];
        if box_distance2(&n.lo, &n.hi, q) > r2 {
            return;
        }
        match n.children {
            Some((left, right)) => {
                self.visit(left, q, r2, found);
                self.visit(right, q, r2, found);
            }
            None => {
                for t in n.start..n.end {
                    if distance2(&self.points[t], q) <= r2 {
                        found(self.index[t]);
                    }
                }
            }
        }
    }
}

/// Build the node of `order[start..end]` (and its subtree); return its index.
fn build<const K: usize>(order: &mut [(usize, [f64; K])], start: usize, end: usize, nodes: &mut Vec<Node<K>>) -> usize {
    let mut lo = [f64::INFINITY; K];
    let mut hi = [f64::NEG_INFINITY; K];
    for (_, p) in &order[start..end] {
        for k in 0..K {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let id = nodes.len();
    nodes.push(Node {
        lo,
        hi,
        start,
        end,
        children: None,
    });
    if end - start > LEAF {
        let axis = (0..K)
            .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
            .unwrap_or(0);
        let mid = start + (end - start) / 2;
        order[start..end].select_nth_unstable_by(mid - start, |a, b| a.1[axis].total_cmp(&b.1[axis]));
        let left = build(order, start, mid, nodes);
        let right = build(order, mid, end, nodes);
        nodes[id].children = Some((left, right));
    }
    id
}

/// `sum((p - q)**2)`, left to right, as NumPy sums a short last axis.
#[inline]
pub(crate) fn distance2<const K: usize>(p: &[f64; K], q: &[f64; K]) -> f64 {
    let mut d2 = 0.0;
    for k in 0..K {
        let d = p[k] - q[k];
        d2 += d * d;
    }
    d2
}

/// The squared distance from `q` to the box `[lo, hi]`, computed like [`distance2`] with
/// the nearest face in place of the point.
#[inline]
fn box_distance2<const K: usize>(lo: &[f64; K], hi: &[f64; K], q: &[f64; K]) -> f64 {
    let mut d2 = 0.0;
    for k in 0..K {
        let gap = if q[k] < lo[k] {
            lo[k] - q[k]
        } else if q[k] > hi[k] {
            q[k] - hi[k]
        } else {
            0.0
        };
        d2 += gap * gap;
    }
    d2
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic pseudo-random sequence in [0, 1) (64-bit LCG, top 53 bits).
    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    fn sorted_within<const K: usize>(tree: &KdTree<K>, q: &[f64; K], r2: f64) -> Vec<usize> {
        let mut got = Vec::new();
        tree.within(q, r2, &mut |i| got.push(i));
        got.sort_unstable();
        got
    }

    #[test]
    fn equals_brute_force_on_random_and_duplicate_points() {
        let mut seed = 7;
        // 500 random 3-D points, on a coarse grid so that many share coordinates and many
        // distances are exactly the radius, plus 100 copies of one point.
        let mut points: Vec<[f64; 3]> = (0..500)
            .map(|_| [(lcg(&mut seed) * 8.0).floor(), (lcg(&mut seed) * 8.0).floor(), 0.5])
            .collect();
        points.extend(std::iter::repeat_n([3.0, 4.0, 0.5], 100));
        let tree = KdTree::new(points.clone());
        for r2 in [0.0, 1.0, 2.0, 25.0, 1e9] {
            for q in [[0.0, 0.0, 0.5], [3.0, 4.0, 0.5], [2.5, 7.0, 1.5], [100.0, -3.0, 0.5]] {
                let want: Vec<usize> = (0..points.len()).filter(|&i| distance2(&points[i], &q) <= r2).collect();
                assert_eq!(sorted_within(&tree, &q, r2), want, "q {q:?}, r2 {r2}");
            }
        }
    }

    #[test]
    fn inclusive_at_the_radius() {
        // (3, 4) is at distance exactly 5 from the origin: 9 + 16 = 25 <= 5 * 5.
        let tree = KdTree::new(vec![[3.0, 4.0], [0.0, 5.0000001], [-5.0, 0.0]]);
        assert_eq!(sorted_within(&tree, &[0.0, 0.0], 25.0), vec![0, 2]);
        assert_eq!(sorted_within(&tree, &[0.0, 0.0], 24.999999), Vec::<usize>::new());
    }
}
