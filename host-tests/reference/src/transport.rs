//! Exact transportation problem by the transportation simplex method (a
//! network simplex on the complete bipartite graph).

/// Relative reduced-cost tolerance: a non-basic cell enters only if its
/// reduced cost is below `-REDUCED_TOL * max cost`. Potentials are recomputed
/// from the costs at every pivot, so their rounding error stays near 1e-16
/// relative and this bound only keeps rounding noise from entering.
const REDUCED_TOL: f64 = 1e-12;

/// Basis state: a spanning tree on `m` supply nodes (`0..m`) and `n` demand
/// nodes (`m..m+n`) whose edges are the basic cells.
struct Basis<'a> {
    m: usize,
    n: usize,
    cost: &'a [f64],
    flow: Vec<f64>,
    basic: Vec<bool>,
    adj: Vec<Vec<usize>>,
}

impl Basis<'_> {
    fn add(&mut self, i: usize, j: usize, x: f64) {
        self.flow[i * self.n + j] = x;
        self.basic[i * self.n + j] = true;
        self.adj[i].push(self.m + j);
        self.adj[self.m + j].push(i);
    }

    fn remove(&mut self, i: usize, j: usize) {
        self.flow[i * self.n + j] = 0.0;
        self.basic[i * self.n + j] = false;
        let (row, col) = (i, self.m + j);
        self.adj[row].retain(|&x| x != col);
        self.adj[col].retain(|&x| x != row);
    }

    /// Potentials `u` (supply) and `v` (demand) with `u_i + v_j = c_ij` on
    /// every basic cell, `u_0 = 0`.
    fn potentials(&self, u: &mut [f64], v: &mut [f64], stack: &mut Vec<usize>, seen: &mut [bool]) {
        seen.fill(false);
        u[0] = 0.0;
        seen[0] = true;
        stack.clear();
        stack.push(0);
        while let Some(node) = stack.pop() {
            for &next in &self.adj[node] {
                if seen[next] {
                    continue;
                }
                seen[next] = true;
                if node < self.m {
                    let j = next - self.m;
                    v[j] = self.cost[node * self.n + j] - u[node];
                } else {
                    let j = node - self.m;
                    u[next] = self.cost[next * self.n + j] - v[j];
                }
                stack.push(next);
            }
        }
    }

    /// Tree path from node `from` to node `to`, as a node list.
    fn path(
        &self,
        from: usize,
        to: usize,
        parent: &mut [usize],
        stack: &mut Vec<usize>,
    ) -> Vec<usize> {
        const NONE: usize = usize::MAX;
        parent.fill(NONE);
        parent[from] = from;
        stack.clear();
        stack.push(from);
        while let Some(node) = stack.pop() {
            if node == to {
                break;
            }
            for &next in &self.adj[node] {
                if parent[next] == NONE {
                    parent[next] = node;
                    stack.push(next);
                }
            }
        }
        let mut path = vec![to];
        let mut node = to;
        while node != from {
            node = parent[node];
            path.push(node);
        }
        path.reverse();
        path
    }

    fn cell(&self, a: usize, b: usize) -> (usize, usize) {
        if a < self.m {
            (a, b - self.m)
        } else {
            (b, a - self.m)
        }
    }
}

/// Least-cost start: cells in order of increasing cost each take as much
/// flow as their row and column still allow. Every allocation exhausts its
/// row or its column, so the allocated cells form a forest; zero-flow cells
/// (cheapest first) then join its trees into the spanning tree a basis needs.
fn initial_basis(basis: &mut Basis, supply: &[f64], demand: &[f64]) {
    let (m, n) = (basis.m, basis.n);
    let mut order: Vec<usize> = (0..m * n).collect();
    order.sort_unstable_by(|&a, &b| basis.cost[a].total_cmp(&basis.cost[b]));
    let (mut s, mut d) = (supply.to_vec(), demand.to_vec());
    let mut comp: Vec<usize> = (0..m + n).collect();
    fn root(comp: &mut [usize], mut x: usize) -> usize {
        while comp[x] != x {
            comp[x] = comp[comp[x]];
            x = comp[x];
        }
        x
    }
    let mut placed = 0;
    for &c in &order {
        let (i, j) = (c / n, c % n);
        if s[i] > 0.0 && d[j] > 0.0 {
            let x = s[i].min(d[j]);
            s[i] -= x;
            d[j] -= x;
            basis.add(i, j, x);
            let (a, b) = (root(&mut comp, i), root(&mut comp, m + j));
            comp[a] = b;
            placed += 1;
        }
    }
    for &c in &order {
        if placed == m + n - 1 {
            break;
        }
        let (i, j) = (c / n, c % n);
        let (a, b) = (root(&mut comp, i), root(&mut comp, m + j));
        if a != b && !basis.basic[c] {
            basis.add(i, j, 0.0);
            comp[a] = b;
            placed += 1;
        }
    }
}

/// Minimum of `sum_ij cost[i * n + j] * x_ij` over transport plans `x >= 0`
/// with row sums `supply` and column sums `demand` (which must have equal
/// totals up to rounding; masses non-negative, costs finite).
///
/// Exact: the simplex stops at a basic optimal solution (no reduced cost
/// below `-1e-12` of the largest cost). Starts from the least-cost rule,
/// prices by block search (Dantzig's rule within blocks of about `sqrt(m n)`
/// cells), and switches to Bland's rule for good
/// after a run of degenerate pivots so that it cannot cycle. Should the
/// iteration budget run out anyway, the result comes from the (slower)
/// successive-shortest-path solver [`crate::min_cost_transport`].
///
/// # Panics
/// If `cost.len() != supply.len() * demand.len()`.
pub fn transport_simplex(supply: &[f64], demand: &[f64], cost: &[f64]) -> f64 {
    transport_simplex_checked(supply, demand, cost)
        .unwrap_or_else(|| crate::min_cost_transport(supply, demand, cost))
}

/// [`transport_simplex`] without the fallback: `None` if the iteration
/// budget (`100 (m + n)^2 + 1000` pivots) runs out, which tests use to make
/// sure the simplex itself, not the fallback, produced a result.
///
/// # Panics
/// If `cost.len() != supply.len() * demand.len()`.
pub fn transport_simplex_checked(supply: &[f64], demand: &[f64], cost: &[f64]) -> Option<f64> {
    let (m, n) = (supply.len(), demand.len());
    assert_eq!(cost.len(), m * n, "cost matrix is not {m}x{n}");
    if m == 0 || n == 0 {
        return Some(0.0);
    }
    let mut basis = Basis {
        m,
        n,
        cost,
        flow: vec![0.0; m * n],
        basic: vec![false; m * n],
        adj: vec![Vec::new(); m + n],
    };
    initial_basis(&mut basis, supply, demand);

    let cmax = cost.iter().fold(0.0f64, |a, &c| a.max(c.abs()));
    let tol = REDUCED_TOL * cmax.max(f64::MIN_POSITIVE);
    let (mut u, mut v) = (vec![0.0; m], vec![0.0; n]);
    let mut seen = vec![false; m + n];
    let mut parent = vec![0; m + n];
    let mut stack = Vec::new();
    let mut bland = false;
    let mut cursor = 0;
    let block = (((m * n) as f64).sqrt() as usize).max(16);
    let mut degenerate_run = 0;
    let budget = 100 * (m + n) * (m + n) + 1000;
    for _ in 0..budget {
        basis.potentials(&mut u, &mut v, &mut stack, &mut seen);
        let entering = if bland {
            // Bland: the first improving cell in a fixed order.
            (0..m * n)
                .find(|&c| !basis.basic[c] && cost[c] - u[c / n] - v[c % n] < -tol)
                .map(|c| (c / n, c % n))
        } else {
            // Block search: scan from where the last search stopped and take
            // the best cell of the first block holding an improving one. A
            // full round without one proves optimality.
            let mut entering = None;
            let mut best = -tol;
            for scanned in 1..=m * n {
                let c = cursor;
                cursor = if cursor + 1 == m * n { 0 } else { cursor + 1 };
                if !basis.basic[c] {
                    let r = cost[c] - u[c / n] - v[c % n];
                    if r < best {
                        best = r;
                        entering = Some((c / n, c % n));
                    }
                }
                if scanned % block == 0 && entering.is_some() {
                    break;
                }
            }
            entering
        };
        let Some((ei, ej)) = entering else {
            return Some(basis.flow.iter().zip(cost).map(|(x, c)| x * c).sum());
        };
        // Cycle: entering cell (+), then alternately (-) and (+) along the
        // tree path from its supply node to its demand node.
        let path = basis.path(ei, m + ej, &mut parent, &mut stack);
        let edges: Vec<(usize, usize)> = path.windows(2).map(|w| basis.cell(w[0], w[1])).collect();
        let mut leaving = edges[0];
        let mut theta = f64::INFINITY;
        for &(i, j) in edges.iter().step_by(2) {
            let x = basis.flow[i * n + j];
            let better =
                x < theta || (bland && x == theta && i * n + j < leaving.0 * n + leaving.1);
            if better {
                theta = x;
                leaving = (i, j);
            }
        }
        for (t, &(i, j)) in edges.iter().enumerate() {
            if t % 2 == 0 {
                basis.flow[i * n + j] -= theta;
            } else {
                basis.flow[i * n + j] += theta;
            }
        }
        basis.remove(leaving.0, leaving.1);
        basis.add(ei, ej, theta);
        if theta == 0.0 {
            degenerate_run += 1;
            if degenerate_run > m + n {
                bland = true;
            }
        } else {
            degenerate_run = 0;
        }
    }
    None
}
