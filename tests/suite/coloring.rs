//! Graph colouring on the device (`warp_runtime::sparse::{Adjacency, Coloring}`): the
//! adjacency of edges and of constraints against a host construction, entry for entry; the
//! colours against a host Jones-Plassmann with the same priorities, colour for colour (so every
//! property follows: no edge inside a colour, at most max degree + 1 colours, every vertex
//! coloured), checked directly too; `order` and `offsets` against a stable sort on the host;
//! the same colours at 1, 2 and 4 CPU threads, and on a GPU the same as the CPU's; faults of
//! endpoints out of range; empty graphs.

use std::collections::BTreeSet;

use glam::IVec2;
use warp_lang as wp;
use warp_runtime::sparse::{Adjacency, Coloring};
use wp::FaultKind;

use crate::{arr, host};

backend_tests!(
    random_graphs,
    grid_graph,
    chain_constraints,
    cloth_constraints,
    same_colours_at_any_thread_count,
    out_of_range_endpoints_fault,
    empty_graphs,
    high_degree_uses_the_second_window,
    bad_arguments,
);

/// A reproducible stream (64-bit LCG, high bits): the graphs need no quality, only variety.
struct Lcg(u64);
impl Lcg {
    fn below(&mut self, n: u32) -> i32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 33) % n as u64) as i32
    }
}

/// The neighbour sets of `n` vertices joined by `edges` (both ways, self-loops dropped).
fn host_adjacency(n: usize, edges: &[IVec2]) -> Vec<BTreeSet<i32>> {
    let mut adj = vec![BTreeSet::new(); n];
    for e in edges {
        if e.x != e.y {
            adj[e.x as usize].insert(e.y);
            adj[e.y as usize].insert(e.x);
        }
    }
    adj
}

/// The constraint graph on the host: constraints adjacent when they share a particle.
fn host_constraint_adjacency(n: usize, c: &[IVec2]) -> Vec<BTreeSet<i32>> {
    let mut by_particle = vec![vec![]; n];
    for (i, e) in c.iter().enumerate() {
        by_particle[e.x as usize].push(i as i32);
        if e.y != e.x {
            by_particle[e.y as usize].push(i as i32);
        }
    }
    let mut adj = vec![BTreeSet::new(); c.len()];
    for list in &by_particle {
        for &a in list {
            for &b in list {
                if a != b {
                    adj[a as usize].insert(b);
                }
            }
        }
    }
    adj
}

/// `g`'s rows read back, checked to be `want` exactly (ascending, no repeat, no self-loop).
#[track_caller]
fn assert_adjacency(g: &Adjacency, want: &[BTreeSet<i32>]) {
    assert_eq!(g.len(), want.len());
    let off = host(g.offsets());
    let cols = host(g.columns());
    let nnz: usize = want.iter().map(|s| s.len()).sum();
    assert_eq!(g.nnz().unwrap(), nnz);
    assert_eq!(off[0], 0);
    for (v, s) in want.iter().enumerate() {
        let row = &cols[off[v] as usize..off[v + 1] as usize];
        let want_row: Vec<i32> = s.iter().copied().collect();
        assert_eq!(row, want_row, "vertex {v}'s neighbours");
    }
}

/// lowbias32, the library's priority hash (restated: the test holds it to the documented
/// priorities `(hash32(v ^ seed), v)`).
fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Jones-Plassmann on the host, round by round as documented.
fn host_colours(adj: &[BTreeSet<i32>], seed: u32) -> Vec<i32> {
    let prio = |v: i32| (hash32(v as u32 ^ seed), v);
    let mut c = vec![-1; adj.len()];
    while c.contains(&-1) {
        let prev = c.clone();
        for (v, nb) in adj.iter().enumerate() {
            if prev[v] >= 0 {
                continue;
            }
            let wins = nb
                .iter()
                .all(|&u| prev[u as usize] >= 0 || prio(u) < prio(v as i32));
            if wins {
                let taken: BTreeSet<i32> = nb.iter().map(|&u| prev[u as usize]).collect();
                c[v] = (0..).find(|k| !taken.contains(k)).unwrap();
            }
        }
    }
    c
}

/// Colours `g` with `seed` and checks everything against the host: the colours equal the host
/// Jones-Plassmann's; no edge has one colour at both ends; at most max degree + 1 colours, each
/// with a vertex; `order` is the stable sort of the vertices by colour and `offsets` its runs.
/// On a GPU the colouring of the same graph on the CPU gives the same three arrays. Returns
/// the colour count.
#[track_caller]
fn check_colouring(g: &Adjacency, adj: &[BTreeSet<i32>], seed: u32, dev: &wp::Device) -> usize {
    let c = Coloring::new(g, seed).unwrap();
    let colors = host(&c.colors);
    assert_eq!(colors, host_colours(adj, seed), "colours against the host");
    for (v, nb) in adj.iter().enumerate() {
        for &u in nb {
            assert_ne!(
                colors[v], colors[u as usize],
                "edge ({v}, {u}) inside a colour"
            );
        }
    }
    let degree = adj.iter().map(|s| s.len()).max().unwrap_or(0);
    let count = c.count();
    assert!(count <= degree + 1, "{count} colours, max degree {degree}");
    assert!(colors.iter().all(|&k| (0..count as i32).contains(&k)));
    let mut want_order: Vec<i32> = (0..adj.len() as i32).collect();
    want_order.sort_by_key(|&v| colors[v as usize]);
    assert_eq!(host(&c.order), want_order);
    let mut want_off = vec![0i32; count + 1];
    for &k in &colors {
        want_off[k as usize + 1] += 1;
    }
    for k in 0..count {
        assert!(want_off[k + 1] > 0, "colour {k} has no vertex");
        want_off[k + 1] += want_off[k];
    }
    assert_eq!(host(&c.offsets), want_off);
    let ranges = c.ranges().unwrap();
    assert_eq!(ranges.len(), count);
    if dev.is_cuda() {
        let cpu = wp::cpu();
        let cols = host(g.columns());
        let gc = Adjacency::from_edges(
            adj.len(),
            &arr(
                &adj.iter()
                    .enumerate()
                    .flat_map(|(v, s)| s.iter().map(move |&u| IVec2::new(v as i32, u)))
                    .collect::<Vec<_>>(),
                &cpu,
            ),
        )
        .unwrap();
        assert_eq!(host(gc.offsets()), host(g.offsets()));
        assert_eq!(
            &host(gc.columns())[..gc.nnz().unwrap()],
            &cols[..g.nnz().unwrap()]
        );
        let cc = Coloring::new(&gc, seed).unwrap();
        assert_eq!(host(&cc.colors), colors, "GPU colours against the CPU's");
        assert_eq!(host(&cc.order), host(&c.order));
        assert_eq!(host(&cc.offsets), host(&c.offsets));
    }
    count
}

/// Random graphs of 1 to 3000 vertices, sparse to dense, with repeated edges, both orders
/// and self-loops; each coloured with two seeds.
fn random_graphs(dev: &wp::Device) {
    let mut rng = Lcg(7);
    for &(n, m) in &[
        (1usize, 3usize),
        (2, 1),
        (50, 40),
        (300, 2000),
        (3000, 9000),
        (200, 8000),
    ] {
        let edges: Vec<IVec2> = (0..m)
            .map(|_| IVec2::new(rng.below(n as u32), rng.below(n as u32)))
            .collect();
        let g = Adjacency::from_edges(n, &arr(&edges, dev)).unwrap();
        let adj = host_adjacency(n, &edges);
        assert_adjacency(&g, &adj);
        for seed in [0, 12345] {
            let count = check_colouring(&g, &adj, seed, dev);
            println!("{n} vertices, {m} edges, seed {seed}: {count} colours");
        }
    }
}

/// A 30 x 40 grid with 4-neighbour edges: max degree 4, so at most 5 colours.
fn grid_graph(dev: &wp::Device) {
    let (w, h) = (30i32, 40i32);
    let id = |x: i32, y: i32| y * w + x;
    let mut edges = vec![];
    for y in 0..h {
        for x in 0..w {
            if x + 1 < w {
                edges.push(IVec2::new(id(x, y), id(x + 1, y)));
            }
            if y + 1 < h {
                edges.push(IVec2::new(id(x, y + 1), id(x, y)));
            }
        }
    }
    let n = (w * h) as usize;
    let g = Adjacency::from_edges(n, &arr(&edges, dev)).unwrap();
    let adj = host_adjacency(n, &edges);
    assert_adjacency(&g, &adj);
    let count = check_colouring(&g, &adj, 1, dev);
    assert!(count <= 5);
}

/// The springs of 3 chains of 20 (the springs scene's): each spring is adjacent to its
/// chain's previous and next spring only, so each chain is a path (2 or 3 colours).
fn chain_constraints(dev: &wp::Device) {
    let (chains, segs) = (3usize, 20usize);
    let particles = segs + 1;
    let c: Vec<IVec2> = (0..chains)
        .flat_map(|ch| {
            (0..segs).map(move |s| {
                let p = (ch * particles + s) as i32;
                IVec2::new(p, p + 1)
            })
        })
        .collect();
    let g = Adjacency::of_constraints(chains * particles, &arr(&c, dev)).unwrap();
    let adj = host_constraint_adjacency(chains * particles, &c);
    for (i, s) in adj.iter().enumerate() {
        let k = i % segs;
        assert_eq!(s.len(), if k == 0 || k == segs - 1 { 1 } else { 2 });
    }
    assert_adjacency(&g, &adj);
    let count = check_colouring(&g, &adj, 0, dev);
    assert!((2..=3).contains(&count), "{count}");
}

/// A 12 x 9 cloth's structural, shear and bending springs (an implicit cloth's constraints):
/// the colours of its constraint graph give sets of springs that share no particle.
fn cloth_constraints(dev: &wp::Device) {
    let (w, h) = (12i32, 9i32);
    let id = |x: i32, y: i32| y * w + x;
    let mut c = vec![];
    for y in 0..h {
        for x in 0..w {
            for (dx, dy) in [(1, 0), (0, 1), (1, 1), (1, -1), (2, 0), (0, 2)] {
                let (u, v) = (x + dx, y + dy);
                if (0..w).contains(&u) && (0..h).contains(&v) {
                    c.push(IVec2::new(id(x, y), id(u, v)));
                }
            }
        }
    }
    let n = (w * h) as usize;
    let g = Adjacency::of_constraints(n, &arr(&c, dev)).unwrap();
    let adj = host_constraint_adjacency(n, &c);
    assert_adjacency(&g, &adj);
    let count = check_colouring(&g, &adj, 3, dev);
    // Within a colour no two springs share a particle.
    let col = Coloring::new(&g, 3).unwrap();
    let colors = host(&col.colors);
    for k in 0..count as i32 {
        let mut seen = BTreeSet::new();
        for (i, e) in c.iter().enumerate() {
            if colors[i] == k {
                assert!(
                    seen.insert(e.x) && seen.insert(e.y),
                    "colour {k}: spring {i}"
                );
            }
        }
    }
    println!("cloth {w} x {h}: {} springs in {count} colours", c.len());
}

/// The colours do not depend on the scheduling: rayon pools of 1, 2 and 4 threads give the
/// same arrays (on a GPU the computation runs on the device; the CPU's comparison is in
/// `check_colouring`).
fn same_colours_at_any_thread_count(dev: &wp::Device) {
    let mut rng = Lcg(99);
    let n = 20_000usize;
    let edges: Vec<IVec2> = (0..80_000)
        .map(|_| IVec2::new(rng.below(n as u32), rng.below(n as u32)))
        .collect();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let g = Adjacency::from_edges(n, &arr(&edges, dev)).unwrap();
            let c = Coloring::new(&g, 42).unwrap();
            (
                host(g.columns()),
                host(&c.colors),
                host(&c.order),
                host(&c.offsets),
            )
        })
    };
    let one = run(1);
    for t in [2, 4] {
        assert!(run(t) == one, "{t} threads differ from 1");
    }
    let adj = host_adjacency(n, &edges);
    assert_eq!(one.1, host_colours(&adj, 42));
}

/// An endpoint outside `0..n` is a fault naming the function, the argument, the edge and the
/// endpoint (the smallest bad edge; a negative endpoint too).
fn out_of_range_endpoints_fault(dev: &wp::Device) {
    let fault = |r: wp::Result<Adjacency>| match r.and_then(|g| g.nnz()) {
        Err(wp::Error::Fault(f)) => f,
        other => panic!("expected a fault, got {other:?}"),
    };
    let e = [
        IVec2::new(0, 1),
        IVec2::new(2, 2),
        IVec2::new(3, 5),
        IVec2::new(-1, 0),
    ];
    let f = fault(Adjacency::from_edges(5, &arr(&e, dev)));
    assert_eq!(f.kernel, "sparse::Adjacency::from_edges");
    assert_eq!(
        f.kind,
        FaultKind::OutOfBounds {
            arg: "edges",
            index: vec![2, 5],
            shape: vec![4, 5]
        }
    );
    let f = fault(Adjacency::of_constraints(5, &arr(&e[1..], dev)));
    assert_eq!(f.kernel, "sparse::Adjacency::of_constraints");
    assert_eq!(
        f.kind,
        FaultKind::OutOfBounds {
            arg: "constraints",
            index: vec![1, 5],
            shape: vec![3, 5]
        }
    );
    let f = fault(Adjacency::from_edges(5, &arr(&e[3..], dev)));
    assert_eq!(
        f.kind,
        FaultKind::OutOfBounds {
            arg: "edges",
            index: vec![0, -1],
            shape: vec![1, 5]
        }
    );
    assert!(
        f.to_string().contains("sparse::Adjacency::from_edges"),
        "{f}"
    );
    // After the fault the device works on (and a good graph colours).
    let g = Adjacency::from_edges(5, &arr(&e[..2], dev)).unwrap();
    assert_eq!(Coloring::new(&g, 0).unwrap().count(), 2);
}

/// No vertex; vertices without edges (one colour); edges that are all self-loops.
fn empty_graphs(dev: &wp::Device) {
    let none: Vec<IVec2> = vec![];
    let g = Adjacency::from_edges(0, &arr(&none, dev)).unwrap();
    assert!(g.is_empty());
    assert_eq!(g.nnz().unwrap(), 0);
    let c = Coloring::new(&g, 0).unwrap();
    assert_eq!((c.count(), c.len()), (0, 0));
    assert_eq!(host(&c.offsets), [0]);
    let g = Adjacency::from_edges(6, &arr(&none, dev)).unwrap();
    assert_eq!(host(g.offsets()), [0; 7]);
    let c = Coloring::new(&g, 0).unwrap();
    assert_eq!(host(&c.colors), [0; 6]);
    assert_eq!(host(&c.order), [0, 1, 2, 3, 4, 5]);
    assert_eq!(host(&c.offsets), [0, 6]);
    let loops = [IVec2::new(1, 1), IVec2::new(4, 4)];
    let g = Adjacency::from_edges(5, &arr(&loops, dev)).unwrap();
    assert_eq!(g.nnz().unwrap(), 0);
    assert_eq!(Coloring::new(&g, 9).unwrap().count(), 1);
    // No constraint: no vertex.
    let g = Adjacency::of_constraints(10, &arr(&none, dev)).unwrap();
    assert_eq!((g.len(), g.nnz().unwrap()), (0, 0));
}

/// A complete graph on 70 vertices needs 70 colours: past the first 64-colour window.
fn high_degree_uses_the_second_window(dev: &wp::Device) {
    let n = 70;
    let mut edges = vec![];
    for a in 0..n {
        for b in a + 1..n {
            edges.push(IVec2::new(a, b));
        }
    }
    let g = Adjacency::from_edges(n as usize, &arr(&edges, dev)).unwrap();
    let adj = host_adjacency(n as usize, &edges);
    assert_eq!(check_colouring(&g, &adj, 5, dev), 70);
}

/// Arguments checked on the host: an `Err` naming the function, the argument and the values.
fn bad_arguments(dev: &wp::Device) {
    let err = |r: wp::Result<Adjacency>| match r {
        Err(e @ wp::Error::InvalidArgument { .. }) => e.to_string(),
        other => panic!("expected InvalidArgument, got {other:?}"),
    };
    // Not contiguous: every other element of a 2-D array's column.
    let m = wp::Array::<IVec2, 2>::zeros((4, 2), dev).unwrap();
    let col = m.transpose().row(0).unwrap();
    let e = err(Adjacency::from_edges(3, &col));
    assert!(
        e.contains("sparse::Adjacency::from_edges") && e.contains("`edges` is not contiguous"),
        "{e}"
    );
    let e = err(Adjacency::of_constraints(3, &col));
    assert!(
        e.contains("sparse::Adjacency::of_constraints")
            && e.contains("`constraints` is not contiguous"),
        "{e}"
    );
    let none = arr::<IVec2>(&[], dev);
    let e = err(Adjacency::from_edges(i32::MAX as usize, &none));
    assert!(
        e.contains("`n` is 2147483647; it must be at most 2147483646"),
        "{e}"
    );
}
