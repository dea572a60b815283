//! An independent exact transportation solver: successive shortest paths
//! on the flow network source -> supply -> demand -> sink. Slow (dense
//! Dijkstra per augmentation) and kept only to check [`crate::transport_simplex`].

/// Minimum-cost transport of `supply` to `demand` (row-major `m x n` cost
/// matrix), by successive shortest augmenting paths with Johnson potentials.
///
/// Each augmentation pushes the bottleneck of a cheapest residual path, so
/// the flow stays optimal for its value at every step and the final flow is
/// a minimum-cost maximum flow. Residual capacities below `1e-15` of the
/// total supply count as zero so that rounding dust cannot cause endless
/// tiny augmentations.
///
/// # Panics
/// If `cost.len() != supply.len() * demand.len()`.
pub fn min_cost_transport(supply: &[f64], demand: &[f64], cost: &[f64]) -> f64 {
    let (m, n) = (supply.len(), demand.len());
    assert_eq!(cost.len(), m * n, "cost matrix is not {m}x{n}");
    let nodes = m + n + 2;
    let (src, sink) = (m + n, m + n + 1);
    let mut cap = vec![0.0; nodes * nodes];
    let mut arc_cost = vec![0.0; nodes * nodes];
    let mut flow = vec![0.0; nodes * nodes];
    for (i, &s) in supply.iter().enumerate() {
        cap[src * nodes + i] = s;
    }
    for (j, &d) in demand.iter().enumerate() {
        cap[(m + j) * nodes + sink] = d;
    }
    for i in 0..m {
        for j in 0..n {
            cap[i * nodes + m + j] = f64::INFINITY;
            arc_cost[i * nodes + m + j] = cost[i * n + j];
            arc_cost[(m + j) * nodes + i] = -cost[i * n + j];
        }
    }
    let total: f64 = supply.iter().sum();
    let eps = 1e-15 * total.max(f64::MIN_POSITIVE);
    let residual = |flow: &[f64], u: usize, v: usize| cap[u * nodes + v] - flow[u * nodes + v];

    let mut pot = vec![0.0; nodes];
    let mut dist = vec![0.0; nodes];
    let mut prev = vec![usize::MAX; nodes];
    let mut done = vec![false; nodes];
    loop {
        dist.fill(f64::INFINITY);
        prev.fill(usize::MAX);
        done.fill(false);
        dist[src] = 0.0;
        loop {
            let mut u = usize::MAX;
            for x in 0..nodes {
                if !done[x] && dist[x].is_finite() && (u == usize::MAX || dist[x] < dist[u]) {
                    u = x;
                }
            }
            if u == usize::MAX {
                break;
            }
            done[u] = true;
            for v in 0..nodes {
                if done[v] || residual(&flow, u, v) <= eps {
                    continue;
                }
                // Reduced costs are >= 0 in exact arithmetic; clamp the
                // rounding noise so Dijkstra's invariant holds.
                let rc = (arc_cost[u * nodes + v] + pot[u] - pot[v]).max(0.0);
                if dist[u] + rc < dist[v] {
                    dist[v] = dist[u] + rc;
                    prev[v] = u;
                }
            }
        }
        if !dist[sink].is_finite() {
            break;
        }
        let reach = dist[sink];
        for x in 0..nodes {
            pot[x] += dist[x].min(reach);
        }
        let mut push = f64::INFINITY;
        let mut v = sink;
        while v != src {
            let u = prev[v];
            push = push.min(residual(&flow, u, v));
            v = u;
        }
        let mut v = sink;
        while v != src {
            let u = prev[v];
            flow[u * nodes + v] += push;
            flow[v * nodes + u] -= push;
            v = u;
        }
    }
    let mut total_cost = 0.0;
    for i in 0..m {
        for j in 0..n {
            total_cost += flow[i * nodes + m + j] * cost[i * n + j];
        }
    }
    total_cost
}
