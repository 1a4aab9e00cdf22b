//! The lumen's skeleton as a graph that keeps its cycles, and the colon as the longest simple
//! path through it from the rectum.
//!
//! Why not simply the minimum-cost path (paper §4.2) to the farthest point? In real scans the
//! loops of the colon touch each other, and the contacts can be wide: on a real full colon
//! (colon-a, 0.82 × 0.82 × 1.25 mm) eroding the lumen by 4.5 mm still leaves loops joined,
//! while at 5.5 mm the colon itself falls apart. Every shortest or minimum-cost path then
//! takes short cuts through the contacts, and "the point farthest from the rectum" is not the
//! cecum. What does hold is that the colon is one long tube: a path along the whole tube is
//! longer than any path that uses a contact as a short cut, because a short cut skips tube it
//! could otherwise have visited. So:
//!
//! 1. One minimum-cost search from the source (cost per mm 1 + K·((Dmax − Ds)/Dmax)^p, see
//!    `refine::cost_weight_in`), recording each voxel's predecessor:
//!    a shortest-path tree whose paths keep to the middle of the lumen.
//! 2. TEASAR-like branches (Sato et al. 2000): repeatedly the farthest wide voxel (Ds ≥ a
//!    fraction of Dmax) not yet covered is traced back along the tree until it meets the
//!    skeleton; a tube of radius `cover_scale`·Ds + `cover_mm` around the new branch becomes
//!    covered. This gives a tree of branches.
//! 3. Cycles: every lumen voxel belongs to its nearest skeleton voxel through the lumen (one
//!    multi-source search from the whole skeleton: a geodesic Voronoi partition). Where two touching voxels belong to skeleton points far apart along the
//!    skeleton (much farther than the local radius), two search fronts met: around a loop of
//!    the lumen, or across a contact. Each such meeting place (one per cluster) becomes an edge
//!    joining the two skeleton points, so the graph has the lumen's cycles.
//! 4. The branches are cut at junctions and meeting places into a small graph with edge
//!    lengths in mm, and the longest simple path from the source (to the given target, when
//!    there is one) is searched ([`super::longest`]). Its voxels are the raw centerline.

use std::collections::HashMap;

use super::{
    CenterlineOptions,
    longest::{self, longest_path},
};
use crate::{
    Error, Result,
    distance::geodesic::{Search, start_from_inside_in},
    grid::{PadIndex, Padded},
    mem::refilled,
    volume::grid_ijk,
};

#[derive(Clone, Debug)]
pub struct SkeletonOptions {
    /// A branch covers the voxels within `cover_scale`·Ds + `cover_mm` of it.
    pub cover_scale: f64,
    pub cover_mm: f64,
    /// Two fronts meet (a cycle) where touching voxels belong to skeleton points more than
    /// `meet_scale`·(Ds_a + Ds_b) + `meet_mm` apart along the skeleton.
    pub meet_scale: f64,
    pub meet_mm: f64,
    /// Most steps the longest-path search may take (in each block of the graph) before it
    /// keeps the best found.
    pub search_budget: usize,
}

impl Default for SkeletonOptions {
    fn default() -> Self {
        SkeletonOptions {
            cover_scale: 2.0,
            cover_mm: 5.0,
            meet_scale: 3.0,
            meet_mm: 20.0,
            search_budget: 2_000_000,
        }
    }
}

/// A minimum-cost search with predecessors and settling order.
pub(crate) type Tree = Search;

/// The vector of `kept` with the least capacity of at least `len`, taken out; else an empty one.
fn take_room<T>(kept: &mut Vec<Vec<T>>, len: usize) -> Vec<T> {
    kept.iter()
        .enumerate()
        .filter(|(_, v)| v.capacity() >= len)
        .min_by_key(|(_, v)| v.capacity())
        .map(|(i, _)| i)
        .map_or_else(Vec::new, |i| kept.swap_remove(i))
}

/// The arrays of a skeleton search that is done with, kept for the next search (each is taken
/// where it has room): prep traces the centerline again after each round of plugging holes,
/// and on `ctc/prone-tagged` a search's fresh arrays cost it about a quarter of its time in
/// page faults. Empty, the search takes fresh memory.
#[derive(Default)]
pub struct SkeletonMemory {
    f32s: Vec<Vec<f32>>,
    u8s: Vec<Vec<u8>>,
    u32s: Vec<Vec<u32>>,
}

impl SkeletonMemory {
    /// A kept array with room for `len` values (the least such), else an empty one.
    pub(crate) fn f32s(&mut self, len: usize) -> Vec<f32> {
        take_room(&mut self.f32s, len)
    }
    pub(crate) fn u8s(&mut self, len: usize) -> Vec<u8> {
        take_room(&mut self.u8s, len)
    }
    fn u32s(&mut self, len: usize) -> Vec<u32> {
        take_room(&mut self.u32s, len)
    }
    fn keep_u32s(&mut self, v: Vec<u32>) {
        self.u32s.push(v);
    }
    /// A finished search's distances and parents.
    pub(crate) fn keep_search(&mut self, search: Search) {
        self.keep_f32s(search.dist);
        self.keep_u8s(search.parent);
    }
    pub(crate) fn keep_f32s(&mut self, v: Vec<f32>) {
        self.f32s.push(v);
    }
    pub(crate) fn keep_u8s(&mut self, v: Vec<u8>) {
        self.u8s.push(v);
    }
}

/// One skeleton voxel.
#[derive(Clone, Copy, Debug)]
struct Node {
    idx: usize,
    branch: u32,
    /// Length along the skeleton from the source (mm).
    arc: f32,
}

struct Branch {
    /// Skeleton ordinals, from the one next to `attach` to the tip.
    ords: Vec<u32>,
    /// The skeleton ordinal this branch leaves from (None for the first branch, which starts
    /// at the source).
    attach: Option<u32>,
    depth: u32,
}

const COVERED: u8 = 1;
const SKELETON: u8 = 2;

/// Steps 2 and 3 of the module's docs for one search from the source: the skeleton's
/// branches and where their fronts meet. The longest path to any target (step 4) is then
/// cheap: the automatic ends ask for it twice, without and with the cecum placed by anatomy.
pub(crate) struct SkeletonGraph {
    sk: SkeletonTree,
    near: Tree,
    owner: Vec<u32>,
    meetings: Vec<Meeting>,
    source: usize,
}

impl SkeletonGraph {
    /// `tree` is the weighted search from `source`; `ds` is Ds in the padded layout.
    pub(crate) fn new(
        pad: &Padded,
        tree: &Tree,
        ds: &[f32],
        spacing: [f64; 3],
        source: PadIndex,
        opts: &CenterlineOptions,
        memory: &mut SkeletonMemory,
    ) -> SkeletonGraph {
        let source = source.0;
        // 2. Branches.
        let n = pad.inside.len();
        let sk = SkeletonTree::trace(pad, tree, ds, spacing, source, opts, memory.u8s(n));
        // 3. Cycles: the owner of every voxel is the nearest skeleton voxel through the lumen
        // (a geodesic Voronoi partition by the skeleton), reached by the way `near` records.
        let near = pad
            .search(spacing)
            .tree_reusing(memory.u8s(n))
            .start(start_from_inside_in(pad, memory.f32s(pad.search_len())))
            .from(&sk.voxels());
        let owner = sk.owners(&near, memory.u32s(n));
        let meetings = sk.meetings(&near, &owner, ds, opts);
        SkeletonGraph {
            sk,
            near,
            owner,
            meetings,
            source,
        }
    }

    /// Its arrays, for the next search.
    pub(crate) fn recycle(self, memory: &mut SkeletonMemory) {
        memory.keep_search(self.near);
        memory.keep_u8s(self.sk.flags);
        memory.keep_u32s(self.owner);
    }

    /// Step 4, the raw centerline (padded indices, source → target): the longest simple path
    /// from the source through the graph, ending at `target` when given, else where the
    /// longest path ends (the cecum). `tree` and `ds` are those the graph was built from.
    /// Edges through a voxel of `closed` (padded indices, sorted) are left out: where the
    /// path goes once they are walled off, without searching the lumen again.
    pub(crate) fn colon_path(
        &self,
        tree: &Tree,
        ds: &[f32],
        target: Option<PadIndex>,
        closed: &[usize],
        opts: &CenterlineOptions,
    ) -> Result<Vec<PadIndex>> {
        let Self {
            sk,
            near,
            owner,
            meetings,
            source,
        } = self;
        let (source, target) = (*source, target.map(|t| t.0));
        let unreachable =
            || Error::invalid("the target cannot be reached from the source through the lumen");
        if let Some(t) = target
            && !tree.dist[t].is_finite()
        {
            return Err(unreachable());
        }
        let target_owner = match target.map(|t| owner[t]) {
            Some(u32::MAX) => return Err(unreachable()),
            o => o,
        };
        let graph = Graph::build(sk, near, meetings, source, target_owner, closed);
        let goal = target_owner.map(|o| graph.node_of[&o]);
        let lengths: Vec<f32> = graph.edges.iter().map(|e| e.length).collect();
        let (best, _) = longest_path(
            &longest::Graph {
                adj: &graph.adj,
                len: &lengths,
            },
            graph.start,
            goal,
            opts.skeleton.search_budget,
        );
        let best = best.ok_or_else(|| {
            Error::invalid("the target cannot be reached from the source through the skeleton")
        })?;
        let mut out = graph.voxels_along(&best, source);
        if let Some(t) = target {
            // From the target's owner out to the target itself.
            out.extend(sk.walk_to_skeleton(near, t).iter().rev().skip(1));
        }
        let out = erase_returns(&out, ds, sk.dims, sk.sp);
        Ok(out.into_iter().map(PadIndex).collect())
    }
}

/// The skeleton as a tree of branches traced back along the minimum-cost tree (step 2).
struct SkeletonTree {
    nodes: Vec<Node>,
    /// Skeleton ordinal of each skeleton voxel (padded index).
    ord_of: HashMap<usize, u32>,
    branches: Vec<Branch>,
    /// `COVERED` and `SKELETON` per padded voxel.
    flags: Vec<u8>,
    dims: [usize; 3],
    sp: [f32; 3],
}

/// Where two search fronts from skeleton points far apart met (step 3): the skeleton
/// ordinals of the two owners and the two touching voxels.
#[derive(Clone, Copy)]
struct Meeting {
    a: u32,
    b: u32,
    u: usize,
    w: usize,
}

impl SkeletonTree {
    /// TEASAR-like branches: the farthest wide voxel not yet covered, traced back along the
    /// tree to the skeleton, then a tube around it covered; the first branch starts at the
    /// source itself (so that the source is a skeleton voxel).
    fn trace(
        pad: &Padded,
        tree: &Tree,
        ds: &[f32],
        spacing: [f64; 3],
        source: usize,
        opts: &CenterlineOptions,
        flags: Vec<u8>,
    ) -> SkeletonTree {
        let dmax = tree
            .order
            .iter()
            .map(|&v| ds[v as usize])
            .fold(0.0f32, f32::max);
        let floor = (opts.min_width as f32 * dmax).min(dmax);
        // Tip candidates, farthest first.
        let mut cand: Vec<(u32, u32)> = tree
            .order
            .iter()
            .filter(|&&v| ds[v as usize] >= floor && ds[v as usize] > 0.0)
            .map(|&v| (tree.dist[v as usize].to_bits(), v))
            .collect();
        cand.sort_unstable_by(|a, b| b.cmp(a));
        let mut tips: Vec<usize> = cand.iter().map(|c| c.1 as usize).collect();
        if tips.is_empty() {
            tips.push(source);
        }
        let mut sk = SkeletonTree {
            nodes: Vec::new(),
            ord_of: HashMap::new(),
            branches: Vec::new(),
            flags: refilled(flags, pad.inside.len(), 0u8),
            dims: pad.dims,
            sp: spacing.map(|s| s as f32),
        };
        let mut next_tip = 0usize;
        let mut first = true;
        loop {
            let tip = if first {
                next_tip = 1;
                tips[0]
            } else {
                let Some(i) = (next_tip..tips.len()).find(|&i| sk.flags[tips[i]] == 0) else {
                    break;
                };
                next_tip = i + 1;
                tips[i]
            };
            sk.add_branch(tree, ds, tip, first, opts);
            first = false;
            if sk.branches.len() > 20_000 {
                break;
            }
        }
        sk
    }

    /// Traces `tip` back until the skeleton (or the source), adds the branch and covers a
    /// tube around it: balls every third of a radius.
    fn add_branch(
        &mut self,
        tree: &Tree,
        ds: &[f32],
        tip: usize,
        first: bool,
        opts: &CenterlineOptions,
    ) {
        let mut path = vec![tip];
        let mut v = tip;
        let mut attach = None;
        loop {
            if !first && self.flags[v] & SKELETON != 0 {
                path.pop();
                attach = Some(self.ord_of[&v]);
                break;
            }
            match tree.parent_of(v) {
                Some(p) => {
                    v = p;
                    path.push(v);
                }
                None => break,
            }
        }
        if path.is_empty() {
            return;
        }
        path.reverse();
        let b = self.branches.len() as u32;
        let nodes = &self.nodes;
        let (mut arc, mut prev, depth) = match attach {
            Some(a) => (
                nodes[a as usize].arc,
                Some(nodes[a as usize].idx),
                self.branches[nodes[a as usize].branch as usize].depth + 1,
            ),
            None => (0.0, None, 0),
        };
        let mut ords = Vec::with_capacity(path.len());
        for &v in &path {
            if let Some(p) = prev {
                arc += self.step_len(p, v);
            }
            prev = Some(v);
            let o = self.nodes.len() as u32;
            self.nodes.push(Node {
                idx: v,
                branch: b,
                arc,
            });
            self.ord_of.insert(v, o);
            self.flags[v] |= SKELETON | COVERED;
            ords.push(o);
        }
        let mut since = f32::INFINITY;
        for (i, &o) in ords.iter().enumerate() {
            let nd = self.nodes[o as usize];
            let r = opts.skeleton.cover_scale as f32 * ds[nd.idx] + opts.skeleton.cover_mm as f32;
            if i > 0 {
                since += nd.arc - self.nodes[ords[i - 1] as usize].arc;
            }
            if since >= r / 3.0 || i + 1 == ords.len() {
                stamp(&mut self.flags, self.dims, nd.idx, r, self.sp);
                since = 0.0;
            }
        }
        self.branches.push(Branch {
            ords,
            attach,
            depth,
        });
    }

    /// The length of a step between two voxels (mm).
    fn step_len(&self, a: usize, b: usize) -> f32 {
        let (pa, pb) = (grid_ijk(self.dims, a), grid_ijk(self.dims, b));
        (0..3)
            .map(|k| ((pa[k] as f32 - pb[k] as f32) * self.sp[k]).powi(2))
            .sum::<f32>()
            .sqrt()
    }

    /// Every skeleton voxel, in skeleton order.
    fn voxels(&self) -> Vec<PadIndex> {
        self.nodes.iter().map(|nd| PadIndex(nd.idx)).collect()
    }

    /// The skeleton ordinal owning each voxel `near` reached (`u32::MAX` elsewhere).
    fn owners(&self, near: &Tree, reuse: Vec<u32>) -> Vec<u32> {
        let mut owner = refilled(reuse, self.flags.len(), u32::MAX);
        for &v in &near.order {
            let v = v as usize;
            owner[v] = if self.flags[v] & SKELETON != 0 {
                self.ord_of[&v]
            } else {
                near.parent_of(v).map_or(u32::MAX, |p| owner[p])
            };
        }
        owner
    }

    /// The way from `v` up `near`'s tree to its skeleton voxel, `v` first.
    fn walk_to_skeleton(&self, near: &Tree, v: usize) -> Vec<usize> {
        let mut walk = vec![v];
        while owner_of_walk(&self.flags, walk[walk.len() - 1]) {
            walk.push(near.parent_of(walk[walk.len() - 1]).unwrap());
        }
        walk
    }

    /// Distance along the skeleton between two skeleton voxels.
    fn tree_dist(&self, a: u32, b: u32) -> f32 {
        let (nodes, branches) = (&self.nodes, &self.branches);
        let (mut x, mut y) = (a, b);
        while nodes[x as usize].branch != nodes[y as usize].branch {
            let (bx, by) = (
                nodes[x as usize].branch as usize,
                nodes[y as usize].branch as usize,
            );
            if branches[bx].depth >= branches[by].depth {
                x = branches[bx].attach.unwrap_or(x);
            } else {
                y = branches[by].attach.unwrap_or(y);
            }
        }
        let lca = nodes[x as usize].arc.min(nodes[y as usize].arc);
        nodes[a as usize].arc + nodes[b as usize].arc - 2.0 * lca
    }

    /// Meeting places: touching voxels owned by skeleton points far apart along the
    /// skeleton; one per cluster, the widest place first.
    fn meetings(
        &self,
        near: &Tree,
        owner: &[u32],
        ds: &[f32],
        opts: &CenterlineOptions,
    ) -> Vec<Meeting> {
        let nodes = &self.nodes;
        let (meet_scale, meet_mm) = (
            opts.skeleton.meet_scale as f32,
            opts.skeleton.meet_mm as f32,
        );
        let half: Vec<isize> = near.nbrs.iter().map(|n| n.0).filter(|&o| o > 0).collect();
        // (width, a, b, u, w): sorted as such (the order of equal widths depends on it).
        let mut meets: Vec<(f32, u32, u32, usize, usize)> = Vec::new();
        for &u in &near.order {
            let u = u as usize;
            let a = owner[u];
            if a == u32::MAX {
                continue;
            }
            for &off in &half {
                let w = (u as isize + off) as usize;
                let b = owner[w];
                if b == u32::MAX || b == a {
                    continue;
                }
                let (na, nb) = (nodes[a as usize], nodes[b as usize]);
                let thr = meet_scale * (ds[na.idx] + ds[nb.idx]) + meet_mm;
                let gap = (na.arc - nb.arc).abs();
                if na.branch == nb.branch && gap <= thr {
                    continue;
                }
                if gap > thr || self.tree_dist(a, b) > thr {
                    let (a, b, u, w) = if a < b { (a, b, u, w) } else { (b, a, w, u) };
                    meets.push((ds[u] + ds[w], a, b, u, w));
                }
            }
        }
        meets.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
        let mut kept: Vec<Meeting> = Vec::new();
        for &(_, a, b, u, w) in &meets {
            let m = Meeting { a, b, u, w };
            let (na, nb) = (nodes[m.a as usize], nodes[m.b as usize]);
            let near = kept.iter().any(|k| {
                let (ka, kb) = (nodes[k.a as usize], nodes[k.b as usize]);
                let ra = meet_scale * ds[ka.idx] + meet_mm;
                let rb = meet_scale * ds[kb.idx] + meet_mm;
                let close = |x: Node, y: Node, r: f32| {
                    x.branch == y.branch && (x.arc - y.arc).abs() <= r || x.idx == y.idx
                };
                (close(na, ka, ra) && close(nb, kb, rb)) || (close(na, kb, rb) && close(nb, ka, ra))
            });
            if !near {
                kept.push(m);
            }
        }
        kept
    }
}

/// One edge of the skeleton graph: its end nodes, its length (mm) and its voxels from
/// `from` to `to`.
struct Edge {
    from: usize,
    to: usize,
    length: f32,
    voxels: Vec<usize>,
}

/// The skeleton graph (step 4): nodes at the source, the tips, the junctions, the meetings'
/// ends and the target's owner; edges along the branches between them and across each
/// meeting.
struct Graph {
    /// The skeleton ordinal of each graph node, and back.
    node_ords: Vec<u32>,
    node_of: HashMap<u32, usize>,
    edges: Vec<Edge>,
    /// Per node: (neighbour, edge), longer edges first.
    adj: Vec<Vec<(usize, usize)>>,
    start: usize,
}

impl Graph {
    fn build(
        sk: &SkeletonTree,
        near: &Tree,
        meetings: &[Meeting],
        source: usize,
        target_owner: Option<u32>,
        closed: &[usize],
    ) -> Graph {
        let mut g = Graph {
            node_ords: Vec::new(),
            node_of: HashMap::new(),
            edges: Vec::new(),
            adj: Vec::new(),
            start: 0,
        };
        let src_ord = sk.ord_of[&source];
        g.add_node(src_ord);
        for br in &sk.branches {
            g.add_node(*br.ords.last().unwrap());
            if let Some(a) = br.attach {
                g.add_node(a);
            }
        }
        for m in meetings {
            g.add_node(m.a);
            g.add_node(m.b);
        }
        if let Some(o) = target_owner {
            g.add_node(o);
        }
        for br in &sk.branches {
            let chain: Vec<u32> = br
                .attach
                .into_iter()
                .chain(br.ords.iter().copied())
                .collect();
            let mut last = 0usize;
            for i in 1..chain.len() {
                if let Some(&to) = g.node_of.get(&chain[i]) {
                    g.edges.push(Edge {
                        from: g.node_of[&chain[last]],
                        to,
                        length: sk.nodes[chain[i] as usize].arc
                            - sk.nodes[chain[last] as usize].arc,
                        voxels: chain[last..=i]
                            .iter()
                            .map(|&o| sk.nodes[o as usize].idx)
                            .collect(),
                    });
                    last = i;
                }
            }
        }
        for m in meetings {
            let mut voxels = sk.walk_to_skeleton(near, m.u);
            voxels.reverse();
            voxels.extend(sk.walk_to_skeleton(near, m.w));
            g.edges.push(Edge {
                from: g.node_of[&m.a],
                to: g.node_of[&m.b],
                length: voxels.windows(2).map(|x| sk.step_len(x[0], x[1])).sum(),
                voxels,
            });
        }
        if !closed.is_empty() {
            g.edges
                .retain(|e| e.voxels.iter().all(|v| closed.binary_search(v).is_err()));
        }
        g.adj = vec![Vec::new(); g.node_ords.len()];
        for (e, edge) in g.edges.iter().enumerate() {
            if edge.from != edge.to {
                g.adj[edge.from].push((edge.to, e));
                g.adj[edge.to].push((edge.from, e));
            }
        }
        // Longer edges first: the first paths found are good ones when the budget runs out.
        for l in &mut g.adj {
            l.sort_by(|x, y| g.edges[y.1].length.total_cmp(&g.edges[x.1].length));
        }
        g.start = g.node_of[&src_ord];
        g
    }

    fn add_node(&mut self, ord: u32) -> usize {
        *self.node_of.entry(ord).or_insert_with(|| {
            self.node_ords.push(ord);
            self.node_ords.len() - 1
        })
    }

    /// The voxels along a path of edges from the start node (`source` first).
    fn voxels_along(&self, path: &[usize], source: usize) -> Vec<usize> {
        let mut out = vec![source];
        let mut at = self.start;
        for &e in path {
            let edge = &self.edges[e];
            if edge.from == at {
                out.extend(edge.voxels.iter().skip(1));
                at = edge.to;
            } else {
                out.extend(edge.voxels.iter().rev().skip(1));
                at = edge.from;
            }
        }
        out
    }
}

/// Cuts out every excursion that comes back into the lumen ball (radius Ds) of an earlier
/// voxel: it passed the same place twice (a detour into a contact or round a junction). The
/// straight step that replaces it stays inside that ball, so inside the lumen.
fn erase_returns(path: &[usize], ds: &[f32], dims: [usize; 3], sp: [f32; 3]) -> Vec<usize> {
    let pos: Vec<[f32; 3]> = path
        .iter()
        .map(|&v| {
            let p = grid_ijk(dims, v);
            [
                p[0] as f32 * sp[0],
                p[1] as f32 * sp[1],
                p[2] as f32 * sp[2],
            ]
        })
        .collect();
    let d2 = |a: usize, b: usize| (0..3).map(|k| (pos[a][k] - pos[b][k]).powi(2)).sum::<f32>();
    let mut out = Vec::with_capacity(path.len());
    let mut i = 0;
    while i < path.len() {
        out.push(path[i]);
        let r2 = ds[path[i]] * ds[path[i]];
        // The last voxel of the path inside this one's ball (at least the next one).
        let j = (i + 1..path.len())
            .rev()
            .find(|&j| d2(i, j) < r2)
            .unwrap_or(i + 1);
        i = j;
    }
    out
}

/// True while a walk up the tree from `v` has not yet reached the skeleton.
fn owner_of_walk(flags: &[u8], v: usize) -> bool {
    flags[v] & SKELETON == 0
}

/// Marks the voxels within `r` mm of voxel `c` as covered.
fn stamp(flags: &mut [u8], dims: [usize; 3], c: usize, r: f32, sp: [f32; 3]) {
    let p = grid_ijk(dims, c);
    let ext = [0, 1, 2].map(|a| (r / sp[a]).floor() as isize);
    let lo = [0, 1, 2].map(|a| (p[a] as isize - ext[a]).max(0) as usize);
    let hi = [0, 1, 2].map(|a| ((p[a] as isize + ext[a]) as usize).min(dims[a] - 1));
    let r2 = r * r;
    for k in lo[2]..=hi[2] {
        let dz = (k as f32 - p[2] as f32) * sp[2];
        let rz = r2 - dz * dz;
        if rz < 0.0 {
            continue;
        }
        for j in lo[1]..=hi[1] {
            let dy = (j as f32 - p[1] as f32) * sp[1];
            let ry = rz - dy * dy;
            if ry < 0.0 {
                continue;
            }
            let hx = (ry.sqrt() / sp[0]).floor() as isize;
            let i0 = (p[0] as isize - hx).max(0) as usize;
            let i1 = ((p[0] as isize + hx) as usize).min(dims[0] - 1);
            let row = dims[0] * (j + dims[1] * k);
            for f in &mut flags[row + i0..=row + i1] {
                *f |= COVERED;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use crate::{
        Geometry, Volume,
        centerline::{CenterlineOptions, find_endpoints},
        distance::distance_to_wall,
    };

    const R: f64 = 6.0;
    const LEG: f64 = 80.0;
    const BEND: f64 = 15.0;
    /// Millimetre offset of the tube's own frame inside the volume.
    const OFF: DVec3 = DVec3::new(25.0, 10.0, 8.0);

    /// A serpentine tube (radius 6 mm, 1 mm voxels): leg 1 along +x at y = 0, a half turn,
    /// leg 2 back along −x at y = 30, a half turn, leg 3 along +x at y = 60; 334 mm in all.
    /// With `bridge`, legs 1 and 2 also touch at x = 20 through a contact as wide as the tube,
    /// a short cut of 30 mm past 176 mm of tube, as where loops of a real colon touch.
    fn serpentine(bridge: bool) -> Volume<u8> {
        let g = Geometry::new([130, 90, 16], [1.0; 3], [0.0; 3]).unwrap();
        let capsule = |p: DVec3, a: DVec3, b: DVec3| {
            let t = ((p - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
            p.distance(a + (b - a) * t)
        };
        let half_ring = |p: DVec3, c: DVec3, side: f64| {
            if (p.x - c.x) * side < 0.0 {
                return f64::INFINITY;
            }
            ((p.x - c.x).hypot(p.y - c.y) - BEND).hypot(p.z)
        };
        let data = (0..g.len())
            .map(|idx| {
                let [i, j, k] = g.ijk(idx);
                let p = DVec3::new(i as f64, j as f64, k as f64) - OFF;
                let mut d = capsule(p, DVec3::ZERO, DVec3::new(LEG, 0.0, 0.0))
                    .min(capsule(
                        p,
                        DVec3::new(0.0, 30.0, 0.0),
                        DVec3::new(LEG, 30.0, 0.0),
                    ))
                    .min(capsule(
                        p,
                        DVec3::new(0.0, 60.0, 0.0),
                        DVec3::new(LEG, 60.0, 0.0),
                    ))
                    .min(half_ring(p, DVec3::new(LEG, 15.0, 0.0), 1.0))
                    .min(half_ring(p, DVec3::new(0.0, 45.0, 0.0), -1.0));
                if bridge {
                    d = d.min(capsule(
                        p,
                        DVec3::new(20.0, 0.0, 0.0),
                        DVec3::new(20.0, 30.0, 0.0),
                    ));
                }
                (d < R) as u8
            })
            .collect();
        Volume::from_vec(g, data).unwrap()
    }

    fn check_serpentine(bridge: bool) {
        let m = serpentine(bridge);
        let ds = distance_to_wall(&m).unwrap();
        let seed = [(OFF.x - R + 1.0) as usize, OFF.y as usize, OFF.z as usize];
        let e = find_endpoints(&m, &ds, seed, &CenterlineOptions::default()).unwrap();
        let cl = &e.centerline;
        let pts: Vec<DVec3> = cl
            .points_mm
            .iter()
            .map(|p| DVec3::from_array(*p) - OFF)
            .collect();
        let full = 3.0 * LEG + 2.0 * std::f64::consts::PI * BEND;
        assert!(
            (cl.length_mm - full).abs() < 15.0,
            "bridge {bridge}: length {} mm, the tube is {full} mm",
            cl.length_mm
        );
        assert!(pts[0].length() < 8.0, "starts at {}", pts[0]);
        assert!(
            pts.last().unwrap().distance(DVec3::new(LEG, 60.0, 0.0)) < 8.0,
            "ends at {}",
            pts.last().unwrap()
        );
        // Through the first turn's apex, never through the middle of the contact.
        let near = |q: DVec3| {
            pts.iter()
                .map(|p| p.distance(q))
                .fold(f64::INFINITY, f64::min)
        };
        assert!(
            near(DVec3::new(LEG + BEND, 15.0, 0.0)) < 3.0,
            "misses the first turn"
        );
        assert!(
            near(DVec3::new(20.0, 15.0, 0.0)) > 8.0,
            "takes the short cut"
        );
        for p in &cl.points_mm {
            let q = (DVec3::from_array(*p) / m.geometry().spacing_vec()).round();
            assert_eq!(
                m.get(q.x as usize, q.y as usize, q.z as usize),
                1,
                "point {p:?} outside the lumen"
            );
        }
        assert!(cl.arc_mm.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn serpentine_without_contact() {
        check_serpentine(false);
    }

    #[test]
    fn follows_the_tube_not_the_contact() {
        check_serpentine(true);
    }
}
