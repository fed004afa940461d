//! Collapsing a binary SAH tree into `W`-wide nodes by dynamic programming over the SAH
//! of the wide tree (Ylitie, Karras and Laine, "Efficient incoherent ray traversal on
//! GPUs through compressed wide BVHs", HPG 2017, sec. 3.2).
//!
//! The greedy collapse (open the largest inner child until there are `W`, Dammertz et al.
//! 2008; this crate's until stop 22) decides each node alone, and its nodes near the
//! leaves held two or three children: on the bunny 3023 8-wide nodes of 3.6 children
//! each, against 1538 of 6.1 here (SAH cost -5 %, incoherent closest hits +4-9 %;
//! `docs/perf-accel.md` "Stop 22"). Here every binary subtree `n` gets the cheapest cost
//! `C(n, i)` of standing for it by at most `i` roots of the wide tree (leaves or nodes):
//!
//! - `C(n, 1) = min(C_leaf(n), C_node(n))`, with `C_leaf(n) = A(n) C_isect blocks(n)`
//!   where the subtree's references fit one leaf (a subtree whose binary leaves the wide
//!   tree merges), and `C_node(n) = A(n) C_trav + D(n, W)`;
//! - `D(n, j) = min_k C(left, k) + C(right, j - k)`, the subtree's children spread over at
//!   most `j` slots;
//! - `C(n, i) = min(C(n, i - 1), D(n, i))` for `i > 1`.
//!
//! The costs are those of the binary build ([`BuildParams::traversal_cost`],
//! [`BuildParams::intersection_cost`], blocks of [`BuildParams::leaf_block`]), so both
//! steps minimise the same estimate; [`BuildParams::max_leaf_size`] bounds merged leaves.

use crate::sah::{BuildNode, BuildParams};
use crate::wide::WideNode;

/// Collapses the binary tree `root` into wide nodes; the root is always `nodes[0]` (an
/// inner node, even when the whole tree is one leaf). `leaf(first, count)` stores the
/// references `order[first..first + count]` (a binary leaf, or a subtree's merged) and
/// returns its wide-leaf reference `(child, count)`, `count > 0`.
pub(crate) fn collapse_sah<const W: usize>(
    root: &BuildNode,
    params: &BuildParams,
    leaf: &mut impl FnMut(u32, u32) -> (u32, u32),
) -> Vec<WideNode<W>> {
    let mut table = Table::<W>::default();
    let root_id = table.add(root, params);
    let mut nodes = vec![WideNode::EMPTY];
    let kids = if table.info[root_id].children.is_some() { table.node_roots(root_id) } else { vec![root_id] };
    table.fill(0, &kids, &mut nodes, leaf);
    nodes
}

/// A binary node as the dynamic program sees it.
struct Info<'a> {
    node: &'a BuildNode,
    children: Option<[usize; 2]>,
    /// The subtree's references, `order[first..first + count]`.
    first: u32,
    count: u32,
    /// Whether the references lie contiguously, so that one leaf can take them all.
    contiguous: bool,
}

/// Binary nodes in post-order, with `C(n, i)` and the choice that attains it.
#[derive(Default)]
struct Table<'a, const W: usize> {
    info: Vec<Info<'a>>,
    /// `cost[n][i - 1] = C(n, i)`.
    cost: Vec<[f32; W]>,
    /// `choice[n][0]`: [`LEAF`] or [`NODE`]; `choice[n][i - 1]` for `i > 1`: [`FEWER`]
    /// (`C(n, i - 1)`) or `k`, the left child's share of the `i` roots.
    choice: Vec<[i8; W]>,
    /// The left child's share of the `W` slots when `n` is a wide node.
    node_split: Vec<i8>,
}

const LEAF: i8 = 0;
const NODE: i8 = 1;
const FEWER: i8 = -1;

impl<'a, const W: usize> Table<'a, W> {
    /// Adds the subtree `node` (children first) and returns its index.
    fn add(&mut self, node: &'a BuildNode, params: &BuildParams) -> usize {
        let area = node.bounds().surface_area();
        let leaf_cost =
            |n: u32| area * params.intersection_cost * n.div_ceil(params.leaf_block.max(1) as u32) as f32;
        let BuildNode::Inner { children, .. } = node else {
            let &BuildNode::Leaf { first, count, .. } = node else { unreachable!() };
            let info = Info { node, children: None, first, count, contiguous: true };
            return self.push(info, [leaf_cost(count); W], [LEAF; W], 0);
        };
        let (l, r) = (self.add(&children[0], params), self.add(&children[1], params));
        let (li, ri) = (&self.info[l], &self.info[r]);
        let contiguous = li.contiguous && ri.contiguous && ri.first == li.first + li.count;
        let (first, count) = (li.first, li.count + ri.count);
        let (d_node, k_node) = self.spread(l, r, W);
        let node_cost = area * params.traversal_cost + d_node;
        let fits = contiguous && count as usize <= params.max_leaf_size;
        let leaf_cost = if fits { leaf_cost(count) } else { f32::INFINITY };
        let (mut cost, mut choice) = ([f32::INFINITY; W], [FEWER; W]);
        (cost[0], choice[0]) = if leaf_cost <= node_cost { (leaf_cost, LEAF) } else { (node_cost, NODE) };
        for i in 2..=W {
            let (d, k) = self.spread(l, r, i);
            (cost[i - 1], choice[i - 1]) = if d < cost[i - 2] { (d, k) } else { (cost[i - 2], FEWER) };
        }
        let info = Info { node, children: Some([l, r]), first, count, contiguous };
        self.push(info, cost, choice, k_node)
    }

    fn push(&mut self, info: Info<'a>, cost: [f32; W], choice: [i8; W], node_split: i8) -> usize {
        self.info.push(info);
        self.cost.push(cost);
        self.choice.push(choice);
        self.node_split.push(node_split);
        self.info.len() - 1
    }

    /// `D(n, j)` of the children `l`, `r`, and the left share `k` that attains it.
    fn spread(&self, l: usize, r: usize, j: usize) -> (f32, i8) {
        (1..j)
            .map(|k| (self.cost[l][k - 1] + self.cost[r][j - k - 1], k as i8))
            .fold((f32::INFINITY, 1), |best, c| if c.0 < best.0 { c } else { best })
    }

    /// The wide children of `n` made a wide node.
    fn node_roots(&self, n: usize) -> Vec<usize> {
        let [l, r] = self.info[n].children.expect("an inner binary node");
        let k = self.node_split[n] as usize;
        let mut out = Vec::with_capacity(W);
        self.roots(l, k, &mut out);
        self.roots(r, W - k, &mut out);
        out
    }

    /// The at most `i` roots standing for subtree `n` in its parent's node.
    fn roots(&self, n: usize, i: usize, out: &mut Vec<usize>) {
        if i == 1 {
            out.push(n);
            return;
        }
        match (self.choice[n][i - 1], self.info[n].children) {
            (FEWER, _) | (_, None) => self.roots(n, i - 1, out),
            (k, Some([l, r])) => {
                self.roots(l, k as usize, out);
                self.roots(r, i - k as usize, out);
            }
        }
    }

    /// Fills wide node `index` with the roots `kids`. Inner children are allocated next
    /// to each other, after their parent: `refit` relies on the order, and a node's
    /// children then share pages and adjacent cache lines for the prefetches.
    fn fill(
        &self,
        index: usize,
        kids: &[usize],
        nodes: &mut Vec<WideNode<W>>,
        leaf: &mut impl FnMut(u32, u32) -> (u32, u32),
    ) {
        let mut inner = Vec::with_capacity(W);
        for (slot, &k) in kids.iter().enumerate() {
            let info = &self.info[k];
            let as_leaf = info.children.is_none() || self.choice[k][0] == LEAF;
            let (child, count) = if as_leaf {
                leaf(info.first, info.count)
            } else {
                nodes.push(WideNode::EMPTY);
                inner.push((nodes.len() - 1, k));
                (nodes.len() as u32 - 1, 0)
            };
            let n = &mut nodes[index];
            n.set_child_box(slot, &info.node.bounds());
            n.child[slot] = child;
            n.count[slot] = count;
        }
        for (i, k) in inner {
            let kids = self.node_roots(k);
            self.fill(i, &kids, nodes, leaf);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sah::build_binary;
    use crate::testmesh::SplitMix64;
    use filtrace_core::{Aabb, Vec3};

    /// `n` random boxes in the unit cube, some long and thin.
    fn boxes(n: usize, rng: &mut SplitMix64) -> Vec<Aabb> {
        let mut point = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        (0..n)
            .map(|_| {
                let (a, b) = (point(), point());
                Aabb::from_points([a, a + 0.3 * (b - a)])
            })
            .collect()
    }

    /// The binary nodes of `root`, parents before children.
    fn preorder(root: &BuildNode) -> Vec<&BuildNode> {
        let mut out = vec![root];
        let mut i = 0;
        while i < out.len() {
            if let BuildNode::Inner { children, .. } = out[i] {
                out.extend(children.iter());
            }
            i += 1;
        }
        out
    }

    fn refs(n: &BuildNode) -> u32 {
        match n {
            BuildNode::Leaf { count, .. } => *count,
            BuildNode::Inner { children, .. } => refs(&children[0]) + refs(&children[1]),
        }
    }

    /// The SAH cost of the wide tree `nodes` (leaf slots hold `(first, count)` of the
    /// references) with the collapse's costs, and its leaf ranges.
    fn wide_cost<const W: usize>(nodes: &[WideNode<W>], p: &BuildParams) -> (f32, Vec<(u32, u32)>) {
        let root_box = (0..W).map(|i| nodes[0].child_box(i)).fold(Aabb::EMPTY, Aabb::union);
        let mut cost = p.traversal_cost * root_box.surface_area();
        let mut leaves = Vec::new();
        for n in nodes {
            for i in (0..W).filter(|&i| !n.child_box(i).is_empty()) {
                let area = n.child_box(i).surface_area();
                cost += if n.count[i] == 0 {
                    p.traversal_cost * area
                } else {
                    leaves.push((n.child[i], n.count[i]));
                    p.intersection_cost * n.count[i].div_ceil(p.leaf_block as u32) as f32 * area
                };
            }
        }
        (cost, leaves)
    }

    /// The cheapest wide tree by trying every labelling of the binary inner nodes: a wide
    /// node, a merged leaf (when its references fit one), or opened into its parent.
    fn exhaustive<const W: usize>(root: &BuildNode, p: &BuildParams) -> f32 {
        let nodes = preorder(root);
        let inner: Vec<usize> =
            (0..nodes.len()).filter(|&i| matches!(nodes[i], BuildNode::Inner { .. })).collect();
        let index =
            |n: &BuildNode| nodes.iter().position(|m| std::ptr::eq(*m, n)).expect("a node of the tree");
        let blocks = |n: u32| n.div_ceil(p.leaf_block as u32) as f32;
        let mut best = f32::INFINITY;
        'labels: for code in 0..3usize.pow(inner.len() as u32 - 1) {
            // The root is always a wide node (label 0).
            let mut label = vec![0u8; nodes.len()];
            let mut c = code;
            for &i in &inner[1..] {
                label[i] = (c % 3) as u8;
                c /= 3;
            }
            let mut cost = 0.0;
            let mut wide = vec![root];
            while let Some(n) = wide.pop() {
                cost += p.traversal_cost * n.bounds().surface_area();
                let mut slots = 0;
                let mut open = vec![n];
                while let Some(m) = open.pop() {
                    let BuildNode::Inner { children, .. } = m else { unreachable!() };
                    for k in children.iter() {
                        match (k, label[index(k)]) {
                            (BuildNode::Inner { .. }, 2) => open.push(k),
                            (BuildNode::Inner { .. }, 0) => {
                                slots += 1;
                                wide.push(k);
                            }
                            (_, _)
                                if refs(k) as usize > p.max_leaf_size
                                    && matches!(k, BuildNode::Inner { .. }) =>
                            {
                                continue 'labels
                            }
                            _ => {
                                slots += 1;
                                cost += p.intersection_cost * blocks(refs(k)) * k.bounds().surface_area();
                            }
                        }
                    }
                }
                if slots > W {
                    continue 'labels;
                }
            }
            best = best.min(cost);
        }
        best
    }

    /// Checks the collapse of 40 random trees against [`exhaustive`]; returns how many had
    /// at most 9 inner nodes (the others are skipped).
    fn check<const W: usize>(seed: u64) -> usize {
        let mut rng = SplitMix64(seed);
        let mut checked = 0;
        for case in 0..40 {
            let n = 4 + (rng.next_f32() * 10.0) as usize;
            let params = BuildParams {
                max_leaf_size: 1 + (rng.next_f32() * 3.0) as usize,
                leaf_block: 1 + (rng.next_f32() * 2.0) as usize,
                traversal_cost: [0.3, 1.0, 3.0][case % 3],
                ..BuildParams::fastest_build()
            };
            // Every other tree split down to single boxes, so that merged leaves pay.
            let binary = BuildParams { max_leaf_size: 1, ..params.clone() };
            let binary = if case % 2 == 0 { &binary } else { &params };
            let (Some(root), _) = build_binary(&boxes(n, &mut rng), binary) else { panic!("no tree") };
            let inner = preorder(&root).iter().filter(|n| matches!(n, BuildNode::Inner { .. })).count();
            if inner == 0 || inner > 9 {
                continue;
            }
            checked += 1;
            let nodes = collapse_sah::<W>(&root, &params, &mut |first, count| (first, count));
            let (cost, mut leaves) = wide_cost(&nodes, &params);
            let want = exhaustive::<W>(&root, &params);
            let name = format!("W {W} seed {seed} case {case}: {n} boxes, {inner} inner nodes, {params:?}");
            assert!((cost - want).abs() <= 1e-4 * want, "{name}: collapse {cost}, exhaustive {want}");
            // Every reference in exactly one leaf.
            leaves.sort_unstable();
            let mut next = 0;
            for (first, count) in leaves {
                assert_eq!(first, next, "{name}: leaves {first}..{}", first + count);
                next = first + count;
            }
            assert_eq!(next as usize, n, "{name}");
        }
        checked
    }

    #[test]
    fn collapse_is_the_cheapest_wide_tree() {
        let checked: usize = (1..=6).map(|seed| check::<4>(seed) + check::<8>(seed)).sum();
        assert!(checked > 300, "only {checked} trees small enough to check");
    }
}
