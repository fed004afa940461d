//! The order in which any-hit queries visit the children of a wide node, fixed at build
//! time.
//!
//! An any-hit query stops at the first hit, so it should first enter the child most
//! likely to end it for the least work: testing candidates in decreasing order of
//! success probability over cost minimises the expected cost of a search that stops at
//! the first success (the least-cost testing sequence; Mitten 1960, Simon and Kadane
//! 1975). In a room, the walls' leaves (one or two big triangles, almost certainly hit)
//! then go before the 56k-triangle bunny; in a meadow, the ground before the blades.
//!
//! Both quantities are estimated per child, given that the ray touches the child's box,
//! with the same area ratios as the SAH: by Cauchy and Crofton's formula (Santaló,
//! *Integral Geometry and Geometric Probability*, 1976), a random line that meets a
//! convex box `B` meets a convex body `K` inside it with probability `SA(K) / SA(B)`; a
//! triangle of area `a` counts as a flat body of surface `2 a`. A leaf is hit with
//! probability `min(1, sum 2 a / SA(B))` for one test per packet pair; an inner node
//! with `1 - prod_j (1 - r_j p_j)`, `r_j = SA(B_j) / SA(B)` (children assumed
//! independent), and costs one node test plus each child's work when the search gets
//! there, `1 + sum_j r_j c_j prod_{k < j} (1 - r_k p_k)` over the children in visit
//! order (the SAH's sum, less what earlier hits save). Counting the work of a full
//! traversal instead (the plain SAH sum) ordered the engine's subtrees worse: 10 % more
//! node visits per any-hit ray (docs/perf-accel.md, stop 15).
//!
//! Convention: the most promising child goes into the **last** used slot, and any-hit
//! traversals visit hit children from the last slot down (`wide::push_children`, the
//! 8-ray packet traversals, which push in slot order and pop the last first, and Embree's
//! `traverseAnyHit`). Closest hits sort by distance and do not depend on slot order (the
//! tie rule, `crate::closer`).

use crate::wide::WideNode;
use filtrace_core::Aabb;

/// Chance that a ray touching a subtree's box hits something in it, and the expected work
/// (node visits plus leaf tests) of a full traversal of that subtree.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Odds {
    pub hit: f64,
    pub cost: f64,
}

impl Odds {
    /// Higher first: hit probability per unit of work.
    pub fn priority(self) -> f64 {
        self.hit / self.cost.max(1e-9)
    }

    /// Odds of leaf triangles of total area `area` needing `tests` leaf tests, in a box
    /// of surface area `box_area`.
    pub fn of_leaf(area: f64, box_area: f64, tests: f64) -> Self {
        Self { hit: (2.0 * area / box_area.max(f64::MIN_POSITIVE)).min(1.0), cost: tests }
    }

    /// Odds of a node whose box has surface area `box_area` and whose children are
    /// `(child box area, child odds)` in visit order: one node test, then each child with
    /// the chance that the ray touches its box and no earlier child ended the search.
    pub fn of_node(box_area: f64, children: impl IntoIterator<Item = (f64, Odds)>) -> Self {
        let (mut miss, mut cost) = (1.0, 1.0);
        for (area, o) in children {
            let reach = (area / box_area.max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
            cost += reach * o.cost * miss;
            miss *= 1.0 - reach * o.hit;
        }
        Self { hit: 1.0 - miss, cost }
    }

    /// Odds of a top-level leaf in a box of surface area `box_area` whose objects, tested
    /// one after the other until one is hit, have `(box area, odds)` relative to their
    /// own boxes: an object's root test (counted as 1 in its cost) is paid whether or not
    /// the ray touches its box, the rest only when it does.
    pub fn of_objects(box_area: f64, objects: impl IntoIterator<Item = (f64, Odds)>) -> Self {
        let (mut miss, mut cost) = (1.0, 0.0);
        for (area, o) in objects {
            let reach = (area / box_area.max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
            cost += (1.0 + reach * (o.cost - 1.0).max(0.0)) * miss;
            miss *= 1.0 - reach * o.hit;
        }
        Self { hit: 1.0 - miss, cost }
    }
}

/// Puts the used slots of every node of `nodes` (a tree made by `collapse::collapse_sah`:
/// children after their parents) in increasing [`Odds::priority`], empty slots last;
/// `leaf(box, first, count)` estimates a leaf. Returns the odds of the root relative to
/// the union of its child boxes (the default for an empty tree).
pub(crate) fn order_for_any_hit<const W: usize>(
    nodes: &mut [WideNode<W>],
    leaf: impl Fn(&Aabb, u32, u32) -> Odds,
) -> Odds {
    let mut odds = vec![Odds::default(); nodes.len()];
    for i in (0..nodes.len()).rev() {
        let n = nodes[i];
        let mut used: Vec<(usize, f64, Odds)> = (0..W)
            .filter(|&s| !(n.count[s] == 0 && n.child[s] == 0))
            .map(|s| {
                let b = n.child_box(s);
                let o =
                    if n.count[s] > 0 { leaf(&b, n.child[s], n.count[s]) } else { odds[n.child[s] as usize] };
                (s, b.surface_area() as f64, o)
            })
            .collect();
        let node_area = (0..W).map(|s| n.child_box(s)).fold(Aabb::EMPTY, Aabb::union).surface_area() as f64;
        // Stable: equal priorities keep the builder's order.
        used.sort_by(|a, b| a.2.priority().total_cmp(&b.2.priority()));
        odds[i] = Odds::of_node(node_area, used.iter().rev().map(|&(_, a, o)| (a, o)));
        let mut sorted = WideNode::<W>::EMPTY;
        for (slot, &(s, _, _)) in used.iter().enumerate() {
            sorted.set_child_box(slot, &n.child_box(s));
            sorted.child[slot] = n.child[s];
            sorted.count[slot] = n.count[s];
        }
        nodes[i] = sorted;
    }
    odds.first().copied().unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::Vec3;

    #[test]
    fn odds_follow_the_area_ratios() {
        // A unit square (two triangles of area 1/2) filling a flat box's face: hit for sure.
        let square = Odds::of_leaf(1.0, 2.0, 1.0);
        assert_eq!(square.hit, 1.0);
        // One triangle of the two: half the lines through the box.
        assert_eq!(Odds::of_leaf(0.5, 2.0, 1.0).hit, 0.5);
        // A node with two children of half its area, each hit for sure when reached.
        let n = Odds::of_node(2.0, [(1.0, square), (1.0, square)]);
        // The second child is searched only if the first missed: 1 + 0.5 + 0.5 * 0.5.
        assert_eq!((n.hit, n.cost), (0.75, 1.75));
        assert!(square.priority() > n.priority());
    }

    /// A ray falling through a dense sphere onto a huge ground quad: the any-hit
    /// traversal enters the ground's leaf (certain hit, one test) before any of the
    /// sphere's (with the priorities reversed it enters a sphere leaf first).
    #[test]
    fn any_hit_visits_the_ground_before_the_dense_sphere() {
        let sphere = crate::testmesh::displaced_sphere(16, 0.1);
        let ground = [
            [Vec3::new(-50.0, -2.0, -50.0), Vec3::new(50.0, -2.0, -50.0), Vec3::new(50.0, -2.0, 50.0)],
            [Vec3::new(-50.0, -2.0, -50.0), Vec3::new(50.0, -2.0, 50.0), Vec3::new(-50.0, -2.0, 50.0)],
        ];
        let n = sphere.triangle_count();
        let tri = |i: usize| if i < n { sphere.triangle(i) } else { ground[i - n] };
        let blas =
            crate::blas::Blas::build_from(n + 2, tri, &crate::BuildParams::default(), crate::Simd::Sse);
        let crate::blas::Blas::Bvh4(bvh) = blas else { panic!("expected a 4-wide BVH") };
        for x in [-0.5f32, 0.0, 0.3] {
            let (o, d) = (Vec3::new(x, 5.0, 0.1), Vec3::new(0.01, -1.0, 0.02));
            let mut first = None;
            let mut t_max = f32::INFINITY;
            let visit = |p: u32, count: u32, _: &mut f32| {
                first.get_or_insert((p, count));
                true
            };
            crate::wide::traverse::<_, false>(
                &bvh.nodes,
                &crate::wide::RayBoxes::new(o, d),
                0.0,
                &mut t_max,
                visit,
            );
            let (p, count) = first.expect("the ray hits the ground's box");
            let ids = &bvh.tris.prim_ids[4 * p as usize..4 * (p + count) as usize];
            assert!(ids.contains(&(n as u32)) || ids.contains(&(n as u32 + 1)), "first leaf {ids:?}");
        }
    }

    /// The most promising child ends up last; empty slots stay empty; the slots keep
    /// their boxes and references together.
    #[test]
    fn sorts_used_slots_by_priority() {
        let unit = |x: f32| Aabb::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x + 1.0, 1.0, 1.0));
        let mut node = WideNode::<4>::EMPTY;
        for (slot, (first, count)) in [(0u32, 3u32), (10, 1), (20, 2)].into_iter().enumerate() {
            node.set_child_box(slot, &unit(first as f32));
            node.child[slot] = first;
            node.count[slot] = count;
        }
        let mut nodes = vec![node];
        // Same hit chance, cost = count: the single-packet leaf is the most promising.
        let root = order_for_any_hit(&mut nodes, |_, _, count| Odds { hit: 0.5, cost: count as f64 });
        let n = &nodes[0];
        assert_eq!((n.child, n.count), ([0, 20, 10, 0], [3, 2, 1, 0]));
        for s in 0..3 {
            assert_eq!(n.child_box(s), unit(n.child[s] as f32));
        }
        assert!(n.child_box(3).is_empty());
        assert!(root.hit > 0.0 && root.cost > 1.0);
    }
}
