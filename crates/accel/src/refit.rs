//! Refitting a wide BVH whose primitives moved: the tree keeps its shape, every box is
//! recomputed bottom-up from the primitives' new bounds (the `refit_all` of obvhs, on the
//! collapsed wide nodes). Cheaper than a rebuild, but the tree degrades as things move
//! away from where it was built; [`sah_cost`] measures by how much, so that the caller can
//! rebuild when the cost has grown too far (Kopta et al., "Fast, Effective BVH Updates for
//! Animated Scenes", I3D 2012, use the same SAH-growth trigger).

use crate::wide::WideNode;
use filtrace_core::Aabb;

/// Recomputes every child box of `nodes` (a tree made by `wide::collapse`): a leaf slot
/// gets `leaf_box(first, count)`, an inner slot the union of its node's child boxes.
/// `collapse` allocates children after their parent, so one reverse sweep sees every
/// child before its parent. Boxes are unions (min/max, exact), so a refit tree holds the
/// same boxes a rebuild with the same shape would.
pub(crate) fn refit<const W: usize>(nodes: &mut [WideNode<W>], leaf_box: impl Fn(u32, u32) -> Aabb) {
    for i in (0..nodes.len()).rev() {
        for slot in 0..W {
            let (child, count) = (nodes[i].child[slot], nodes[i].count[slot]);
            let b = if count > 0 {
                leaf_box(child, count)
            } else if child == 0 {
                // The root is never a child: (0, 0) marks an unused slot.
                continue;
            } else {
                node_box(&nodes[child as usize])
            };
            set_child_box(&mut nodes[i], slot, &b);
        }
    }
}

/// The union of a node's child boxes.
pub(crate) fn node_box<const W: usize>(n: &WideNode<W>) -> Aabb {
    (0..W).map(|i| n.child_box(i)).fold(Aabb::EMPTY, Aabb::union)
}

fn set_child_box<const W: usize>(n: &mut WideNode<W>, i: usize, a: &Aabb) {
    for k in 0..3 {
        n.bounds[k][i] = a.min[k];
        n.bounds[k + 3][i] = a.max[k];
    }
}

/// SAH cost of a wide tree relative to its root box: one node visit per inner child and
/// `count` primitive tests per leaf child, each weighted by the child's area over the
/// root's (the expected work of a random ray through the root box). Zero for an empty
/// tree.
pub(crate) fn sah_cost<const W: usize>(nodes: &[WideNode<W>]) -> f64 {
    let Some(root) = nodes.first() else { return 0.0 };
    let root_area = node_box(root).surface_area() as f64;
    if !(root_area.is_finite() && root_area > 0.0) {
        return 0.0;
    }
    let mut cost = 1.0;
    for n in nodes {
        for i in 0..W {
            let b = n.child_box(i);
            if b.is_empty() {
                continue;
            }
            let work = if n.count[i] == 0 { 1.0 } else { n.count[i] as f64 };
            cost += work * b.surface_area() as f64 / root_area;
        }
    }
    cost
}
