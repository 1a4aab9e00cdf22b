//! The longest simple path through the skeleton graph (step 4 of [`super::graph`]).
//!
//! Longest simple path is NP-hard, and the large compartments of a real colon give graphs of
//! a few hundred nodes with a hundred independent cycles (haustra, fluid levels, contacts):
//! one depth-first search over the whole graph spent its budget in the first few cycles it
//! met, kept whatever it had found there, and found no path at all once a hole between two
//! loops was plugged (`ctc/prone-tagged`, 213 nodes, 312 edges, two million steps). So, with
//! a goal:
//!
//! 1. The graph is cut into its biconnected blocks (Hopcroft–Tarjan). A simple path from the
//!    start to the goal passes the blocks on the block–cut tree's path between them, each
//!    from the cut vertex it enters by to the one it leaves by, and no other block.
//! 2. Each block's longest path is searched on its own, with its own budget, depth first,
//!    never into a node from which the block's exit can no longer be reached without a node
//!    already on the path. Every branch tried is then the start of a path, and the first path
//!    comes at once.
//!
//! Without a goal the search is one depth-first search from the start, as before.

/// The graph: per node its (neighbour, edge) pairs; edge lengths by edge.
pub(super) struct Graph<'a> {
    pub adj: &'a [Vec<(usize, usize)>],
    pub len: &'a [f32],
}

/// The longest simple path's edges from `start` (to `goal` when given), and the steps
/// spent; `budget` bounds the steps of each block's search.
pub(super) fn longest_path(
    g: &Graph,
    start: usize,
    goal: Option<usize>,
    budget: usize,
) -> (Option<Vec<usize>>, usize) {
    let Some(goal) = goal else {
        let all = vec![true; g.len.len()];
        return Search::new(g, &all, None, budget).run(start);
    };
    if start == goal {
        return (Some(Vec::new()), 0);
    }
    let blocks = Blocks::of(g);
    let Some(chain) = blocks.chain(g, start, goal) else {
        return (None, 0);
    };
    let mut path = Vec::new();
    let mut spent = 0;
    for (block, from, to) in chain {
        let mut inside = vec![false; g.len.len()];
        for &e in &blocks.edges[block] {
            inside[e] = true;
        }
        let (best, steps) = Search::new(g, &inside, Some(to), budget).run(from);
        spent += steps;
        let Some(best) = best else {
            return (None, spent);
        };
        path.extend(best);
    }
    (Some(path), spent)
}

/// A depth-first search for the longest simple path over the edges `inside`.
struct Search<'a> {
    g: &'a Graph<'a>,
    inside: &'a [bool],
    goal: Option<usize>,
    seen: Vec<bool>,
    path: Vec<usize>,
    best: Option<(f32, Vec<usize>)>,
    steps: usize,
    budget: usize,
    /// Scratch for the reachability test: the stamp of the test that last visited a node.
    stamp: Vec<u32>,
    stamps: u32,
    queue: Vec<usize>,
}

impl<'a> Search<'a> {
    fn new(g: &'a Graph<'a>, inside: &'a [bool], goal: Option<usize>, budget: usize) -> Self {
        let n = g.adj.len();
        Search {
            g,
            inside,
            goal,
            seen: vec![false; n],
            path: Vec::new(),
            best: None,
            steps: 0,
            budget,
            stamp: vec![0; n],
            stamps: 0,
            queue: Vec::new(),
        }
    }

    fn run(mut self, start: usize) -> (Option<Vec<usize>>, usize) {
        self.seen[start] = true;
        self.go(start, 0.0);
        (self.best.map(|b| b.1), self.steps)
    }

    fn go(&mut self, at: usize, acc: f32) {
        if self.goal.is_none_or(|g| g == at) && self.best.as_ref().is_none_or(|b| acc > b.0) {
            self.best = Some((acc, self.path.clone()));
        }
        if self.goal == Some(at) {
            return;
        }
        let g = self.g;
        for &(to, e) in &g.adj[at] {
            if !self.inside[e] || self.seen[to] || self.steps >= self.budget {
                continue;
            }
            self.steps += 1;
            if !self.reaches_goal(to) {
                continue;
            }
            self.seen[to] = true;
            self.path.push(e);
            self.go(to, acc + g.len[e]);
            self.path.pop();
            self.seen[to] = false;
        }
    }

    /// Whether the goal can be reached from `from` by nodes not on the path (always, without
    /// a goal). Its visits count as steps.
    fn reaches_goal(&mut self, from: usize) -> bool {
        let Some(goal) = self.goal else {
            return true;
        };
        self.stamps += 1;
        let s = self.stamps;
        self.queue.clear();
        self.queue.push(from);
        self.stamp[from] = s;
        while let Some(v) = self.queue.pop() {
            if v == goal {
                return true;
            }
            self.steps += 1;
            for &(to, e) in &self.g.adj[v] {
                if self.inside[e] && !self.seen[to] && self.stamp[to] != s {
                    self.stamp[to] = s;
                    self.queue.push(to);
                }
            }
        }
        false
    }
}

/// The graph's biconnected blocks: each block's edges and nodes, and the blocks of each node.
struct Blocks {
    edges: Vec<Vec<usize>>,
    nodes: Vec<Vec<usize>>,
    of_node: Vec<Vec<usize>>,
}

impl Blocks {
    /// Hopcroft–Tarjan, with an explicit stack (graphs of thousands of nodes).
    fn of(g: &Graph) -> Blocks {
        let n = g.adj.len();
        let mut order = vec![usize::MAX; n];
        let mut low = vec![0; n];
        let mut edge_stack: Vec<usize> = Vec::new();
        let mut blocks = Blocks {
            edges: Vec::new(),
            nodes: Vec::new(),
            of_node: vec![Vec::new(); n],
        };
        // Each edge's two nodes.
        let mut ends = vec![(0, 0); g.len.len()];
        for (v, list) in g.adj.iter().enumerate() {
            for &(w, e) in list {
                ends[e] = (v, w);
            }
        }
        let mut counter = 0;
        let mut edge_seen = vec![false; g.len.len()];
        for root in 0..n {
            if order[root] != usize::MAX {
                continue;
            }
            order[root] = counter;
            low[root] = counter;
            counter += 1;
            // (node, the edge it was entered by, next neighbour to look at)
            let mut stack: Vec<(usize, usize, usize)> = vec![(root, usize::MAX, 0)];
            while let Some(&mut (v, via, ref mut next)) = stack.last_mut() {
                if let Some(&(w, e)) = g.adj[v].get(*next) {
                    *next += 1;
                    if e == via || edge_seen[e] {
                        continue;
                    }
                    edge_seen[e] = true;
                    edge_stack.push(e);
                    if order[w] == usize::MAX {
                        order[w] = counter;
                        low[w] = counter;
                        counter += 1;
                        stack.push((w, e, 0));
                    } else {
                        low[v] = low[v].min(order[w]);
                    }
                    continue;
                }
                stack.pop();
                let Some(&(u, _, _)) = stack.last() else {
                    continue;
                };
                low[u] = low[u].min(low[v]);
                if low[v] >= order[u] {
                    // u cuts v's block off: its edges are those pushed since `via`.
                    let at = edge_stack.iter().rposition(|&x| x == via).unwrap_or(0);
                    let block: Vec<usize> = edge_stack.drain(at..).collect();
                    blocks.push(&ends, block);
                }
            }
        }
        blocks
    }

    fn push(&mut self, ends: &[(usize, usize)], edges: Vec<usize>) {
        let b = self.edges.len();
        let mut nodes: Vec<usize> = edges.iter().flat_map(|&e| [ends[e].0, ends[e].1]).collect();
        nodes.sort_unstable();
        nodes.dedup();
        for &v in &nodes {
            self.of_node[v].push(b);
        }
        self.nodes.push(nodes);
        self.edges.push(edges);
    }

    /// The blocks a simple path from `start` to `goal` passes, each with the nodes it is
    /// entered and left by: the path between them in the block–cut tree.
    fn chain(&self, g: &Graph, start: usize, goal: usize) -> Option<Vec<(usize, usize, usize)>> {
        // Block–cut tree nodes: blocks 0..B, then graph nodes B + v.
        let nb = self.edges.len();
        let n = nb + g.adj.len();
        let mut prev = vec![usize::MAX; n];
        let mut queue = std::collections::VecDeque::from([nb + start]);
        prev[nb + start] = nb + start;
        while let Some(x) = queue.pop_front() {
            if x == nb + goal {
                break;
            }
            let next: Vec<usize> = if x < nb {
                self.nodes[x].iter().map(|&v| nb + v).collect()
            } else {
                self.of_node[x - nb].clone()
            };
            for y in next {
                if prev[y] == usize::MAX {
                    prev[y] = x;
                    queue.push_back(y);
                }
            }
        }
        if prev[nb + goal] == usize::MAX {
            return None;
        }
        let mut trail = vec![nb + goal];
        while *trail.last()? != nb + start {
            trail.push(prev[*trail.last()?]);
        }
        trail.reverse();
        // node, block, node, block, ..., node
        Some(
            trail
                .windows(3)
                .step_by(2)
                .map(|w| (w[1], w[0] - nb, w[2] - nb))
                .collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(n: usize, edges: &[(usize, usize, f32)]) -> (Vec<Vec<(usize, usize)>>, Vec<f32>) {
        let mut adj = vec![Vec::new(); n];
        for (e, &(a, b, _)) in edges.iter().enumerate() {
            adj[a].push((b, e));
            adj[b].push((a, e));
        }
        (adj, edges.iter().map(|e| e.2).collect())
    }

    /// A chain of blocks: a triangle 0-1-2 (0–2 short cut), a bridge 2–3, a square 3-4-5-6
    /// with a diagonal 3–5 short cut, and a dead-end branch 4–7 that no path to 5 may take.
    #[test]
    fn the_longest_path_goes_round_each_block_and_skips_dead_ends() {
        let (adj, len) = graph(
            8,
            &[
                (0, 1, 10.0),
                (1, 2, 10.0),
                (0, 2, 1.0),
                (2, 3, 5.0),
                (3, 4, 10.0),
                (4, 6, 10.0),
                (6, 5, 10.0),
                (3, 5, 1.0),
                (4, 7, 50.0),
            ],
        );
        let g = Graph {
            adj: &adj,
            len: &len,
        };
        let (best, _) = longest_path(&g, 0, Some(5), 1000);
        let total: f32 = best.unwrap().iter().map(|&e| len[e]).sum();
        assert_eq!(total, 10.0 + 10.0 + 5.0 + 10.0 + 10.0 + 10.0);
        // Without a goal the dead end is the farthest reach.
        let (best, _) = longest_path(&g, 0, None, 1000);
        let total: f32 = best.unwrap().iter().map(|&e| len[e]).sum();
        assert_eq!(total, 10.0 + 10.0 + 5.0 + 1.0 + 10.0 + 10.0 + 50.0);
        // No path to a node of another component.
        let (adj2, len2) = graph(3, &[(0, 1, 1.0)]);
        let g2 = Graph {
            adj: &adj2,
            len: &len2,
        };
        assert!(longest_path(&g2, 0, Some(2), 1000).0.is_none());
    }

    /// A ladder of many cycles (the large compartment's haustra): a path to the far end is
    /// found within a small budget, and it takes every rung's long side.
    #[test]
    fn a_ladder_of_cycles_is_searched_block_by_block() {
        let rungs = 60;
        let mut edges = Vec::new();
        // Nodes 2i and 2i+1; each cycle: 2i -(long)- 2i+1 and 2i -(short)- 2i+1, then on.
        for i in 0..rungs {
            edges.push((2 * i, 2 * i + 1, 10.0));
            edges.push((2 * i, 2 * i + 1, 1.0));
            edges.push((2 * i + 1, 2 * i + 2, 3.0));
        }
        let (adj, len) = graph(2 * rungs + 1, &edges);
        let g = Graph {
            adj: &adj,
            len: &len,
        };
        let (best, steps) = longest_path(&g, 0, Some(2 * rungs), 10_000);
        let total: f32 = best.unwrap().iter().map(|&e| len[e]).sum();
        assert_eq!(total, rungs as f32 * 13.0);
        assert!(steps < 10_000 * rungs);
    }
}
