//! Graph colouring on the device: [`Adjacency`] (a symmetric pattern without self-loops, from
//! edges or from constraints that share a particle) and [`Coloring`] (Jones-Plassmann with
//! hashed priorities). A colouring splits a Gauss-Seidel sweep over constraints (XPBD, a
//! smoother) into phases whose constraints touch disjoint particles, so each phase runs a
//! thread per constraint with no write conflict.
//!
//! The steps are `color_steps.rs` (`wp_sparse_color.h` on a GPU); the adjacency is assembled
//! by the triplet pipeline of `mod.rs` (a stable sort of `(row, column)` keys, then each run
//! once), so its columns ascend within a row.

use super::color_steps::{Pairs, Report, Round, Sort, Split};
use super::{contiguous, invalid, key_bits, Bsr};
use crate::array::Array;
use crate::backend::{ObjectStep, StepFault};
use crate::device::Device;
use crate::dispatch;
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use crate::primitives::{array_scan_n, compact, radix_sort_pairs, Count};
use glam::IVec2;

/// What `Adjacency::from_edges`' errors and faults are named by.
static EDGE_NAMES: KernelInfo = KernelInfo {
    name: "sparse::Adjacency::from_edges",
    module: "warp_lang::sparse",
    params: &["edges", "edges", "values", "count"],
    ..KernelInfo::BLANK
};

/// What `Adjacency::of_constraints`' errors and faults are named by.
static CONSTRAINT_NAMES: KernelInfo = KernelInfo {
    name: "sparse::Adjacency::of_constraints",
    module: "warp_lang::sparse",
    params: &["constraints", "constraints", "values", "count"],
    ..KernelInfo::BLANK
};

/// Queues `step` unless it has no thread.
fn run<S: ObjectStep>(dev: &Device, s: &S) -> Result<()> {
    if s.len() == 0 {
        return Ok(());
    }
    dispatch::object_step(dev, s)
}

/// The undirected graph of `len()` vertices as a symmetric pattern in compressed sparse row
/// form: vertex `v`'s neighbours are `columns[offsets[v] .. offsets[v + 1]]`, ascending, each
/// once, never `v` itself. As a [`Bsr`]'s structure, the exact entry count `offsets[len()]`
/// lives on the device and `columns` may be longer ([`Adjacency::nnz`] reads the count).
#[derive(Clone, Debug)]
pub struct Adjacency {
    n: usize,
    offsets: Array<i32>,
    columns: Array<i32>,
}

impl Adjacency {
    /// The graph of `n` vertices whose edges are `edges` (pairs of vertices, either order):
    /// each edge joins both ways, a repeated edge counts once, a self-loop `(v, v)` is dropped.
    /// `edges` is contiguous; the graph is on its device, with room for two entries per edge.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `sparse::Adjacency::from_edges` for `n` above
    /// `i32::MAX - 1`, more than `i32::MAX / 2` edges or edges that are not contiguous. An
    /// endpoint outside `0..n` is an [`Error::Fault`] of that name: out of bounds on argument
    /// `edges` with index `[edge, endpoint]` and shape `[edges, n]` (the smallest such edge; on
    /// the CPU at once, on a GPU at the next synchronisation, the graph then holding the
    /// other edges).
    pub fn from_edges(n: usize, edges: &Array<IVec2>) -> Result<Self> {
        Self::build(n, edges, &EDGE_NAMES)
    }

    /// The constraint graph of `constraints` (pairs of particles, as a chain's or a cloth's
    /// springs) over `n` particles: a vertex per constraint, two constraints adjacent when they
    /// share a particle. A colouring of it splits the constraints into sets that touch disjoint
    /// particles.
    ///
    /// Built as the incidence pattern (particle, constraint), then per particle every ordered
    /// pair of its constraints (`k (k - 1)` for a particle of `k`: one read-back of their
    /// total, to size the pairs), then the triplet pipeline. A particle shared by many
    /// constraints costs its pairs on one thread.
    ///
    /// # Errors
    /// As [`Adjacency::from_edges`], named `sparse::Adjacency::of_constraints` with argument
    /// `constraints`; [`Error::InvalidArgument`] when the pairs exceed `i32::MAX`;
    /// [`Error::Capture`] inside a capture (the read-back).
    pub fn of_constraints(n: usize, constraints: &Array<IVec2>) -> Result<Self> {
        let inc = Self::build(n, constraints, &CONSTRAINT_NAMES)?;
        let f = CONSTRAINT_NAMES.name;
        let (m, dev) = (constraints.len(), constraints.device().clone());
        let cap = inc.columns.len() as i32;
        // Each particle's pair count, scanned (exclusive) into each particle's first pair,
        // the total last.
        let starts = Array::<i64>::zeros(n + 1, &dev)?;
        let pairs = |rows: u64, cols: u64, limit: i64| Pairs::<true> {
            offsets: inc.offsets.device_address(),
            columns: inc.columns.device_address(),
            starts: starts.device_address(),
            rows,
            cols,
            limit,
            n: n as i32,
            cap,
        };
        run(&dev, &pairs(0, 0, 0))?;
        array_scan_n(&starts, &starts, n + 1, false)?;
        let total = starts.view(n..n + 1)?.to_vec()?[0].max(0) as usize;
        if total > i32::MAX as usize {
            return Err(invalid(
                f,
                format!(
                    "the constraints sharing a particle make {total} ordered pairs, more than \
                     the {} an i32 index counts",
                    i32::MAX
                ),
            ));
        }
        let rows = Array::<i32>::zeros(total, &dev)?;
        let cols = Array::<i32>::zeros(total, &dev)?;
        run(
            &dev,
            &pairs(rows.device_address(), cols.device_address(), total as i64).step::<false>(),
        )?;
        let values = Array::<f32>::zeros(total, &dev)?;
        let g = Bsr::<f32>::assemble_with(
            m,
            m,
            &rows,
            &cols,
            &values,
            Count::Host(total),
            true,
            &CONSTRAINT_NAMES,
            false,
        )?;
        Ok(Adjacency {
            n: m,
            offsets: g.offsets,
            columns: g.columns,
        })
    }

    /// The edges' triplets (both ways; `incidence` for `of_constraints`: particle, constraint),
    /// the kept ones compacted, then the pipeline: the graph of `from_edges`, or the incidence
    /// pattern of `n` particles by `edges.len()` constraints.
    fn build(n: usize, edges: &Array<IVec2>, names: &'static KernelInfo) -> Result<Self> {
        let f = names.name;
        let incidence = std::ptr::eq(names, &CONSTRAINT_NAMES);
        let arg = names.params[0];
        contiguous(f, arg, edges)?;
        let limit = i32::MAX as usize - 1;
        if n > limit {
            return Err(invalid(
                f,
                format!("`n` is {n}; it must be at most {limit} (i32 indices)"),
            ));
        }
        let m = edges.len();
        if m > i32::MAX as usize / 2 {
            return Err(invalid(
                f,
                format!(
                    "argument `{arg}` has {m} pairs, more than the {} whose two triplets an \
                     i32 counts",
                    i32::MAX / 2
                ),
            ));
        }
        let dev = edges.device().clone();
        let (ncol, t) = (if incidence { m } else { n }, 2 * m);
        let rows = Array::<i32>::zeros(t, &dev)?;
        let cols = Array::<i32>::zeros(t, &dev)?;
        let flags = Array::<i32>::zeros(t, &dev)?;
        let bad = Array::<i32>::zeros(1, &dev)?;
        bad.fill(i32::MAX)?;
        let split = Split {
            edges: edges.device_address(),
            rows: rows.device_address(),
            cols: cols.device_address(),
            flags: flags.device_address(),
            bad: bad.device_address(),
            m: m as i32,
            n: n as i32,
            incidence: incidence as i32,
            pad: 0,
        };
        run(&dev, &split)?;
        run(
            &dev,
            &Report {
                edges: split.edges,
                bad: split.bad,
                m: split.m,
                n: split.n,
                fault: StepFault::new(names),
            },
        )?;
        // The kept triplets to the front (both compactions count the same flags).
        let (kept_rows, kept_cols) = (Array::<i32>::zeros(t, &dev)?, Array::zeros(t, &dev)?);
        let (count, count2) = (Array::<i32>::zeros(1, &dev)?, Array::zeros(1, &dev)?);
        compact(&rows, &flags, &kept_rows, &count)?;
        compact(&cols, &flags, &kept_cols, &count2)?;
        let values = Array::<f32>::zeros(t, &dev)?;
        let g = Bsr::<f32>::assemble_with(
            n,
            ncol,
            &kept_rows,
            &kept_cols,
            &values,
            Count::Device(&count),
            false,
            names,
            false,
        )?;
        Ok(Adjacency {
            n,
            offsets: g.offsets,
            columns: g.columns,
        })
    }

    /// Vertices.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether the graph has no vertex.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The row offsets (`len() + 1`).
    pub fn offsets(&self) -> &Array<i32> {
        &self.offsets
    }

    /// The neighbours, row after row (the first [`Adjacency::nnz`] are the graph's).
    pub fn columns(&self) -> &Array<i32> {
        &self.columns
    }

    /// The entry count `offsets[len()]` (twice the edge count), read back and clamped into
    /// the capacity of [`Adjacency::columns`] as the steps clamp it.
    ///
    /// # Errors
    /// A fault of the queued work, or a read-back inside a capture.
    pub fn nnz(&self) -> Result<usize> {
        let v = self.offsets.view(self.n..self.n + 1)?.to_vec()?[0];
        Ok(v.clamp(0, self.columns.len() as i32) as usize)
    }

    /// The device holding the graph.
    pub fn device(&self) -> &Device {
        self.offsets.device()
    }
}

/// A colouring of an [`Adjacency`]: no two neighbours share a colour.
///
/// `colors[v]` is vertex `v`'s colour, in `0..count()`; `order` lists the vertices by colour,
/// ascending within a colour, and colour `c`'s vertices are `order[offsets[c] ..
/// offsets[c + 1]]` (`offsets` has `count() + 1` entries). Every colour below `count()` has a
/// vertex.
///
/// ```
/// # use warp_runtime as wp;
/// use glam::IVec2;
/// use wp::sparse::{Adjacency, Coloring};
/// let dev = wp::cpu();
/// // Three springs of a chain of four particles: the middle one touches both others.
/// let springs = [IVec2::new(0, 1), IVec2::new(1, 2), IVec2::new(2, 3)];
/// let g = Adjacency::of_constraints(4, &wp::Array::from_slice(&springs, &dev)?)?;
/// let c = Coloring::new(&g, 0)?;
/// let colors = c.colors.to_vec()?;
/// assert!(colors[0] != colors[1] && colors[1] != colors[2]);
/// assert!(c.count() <= 3); // at most the largest degree (2) plus one
/// for r in c.ranges()? {
///     // A kernel launched over `r.len()` threads reads its spring from `order[r.start + i]`.
///     assert!(!r.is_empty());
/// }
/// # Ok::<(), wp::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct Coloring {
    /// Each vertex's colour.
    pub colors: Array<i32>,
    /// The vertices sorted by colour (stably: ascending within a colour).
    pub order: Array<i32>,
    /// Where each colour's vertices start in `order`, and `len()` last.
    pub offsets: Array<i32>,
}

impl Coloring {
    /// Colours `g` by Jones-Plassmann rounds on its device. Vertex `v`'s priority is
    /// `(hash32(v ^ seed), v)`, a total order; in each round an uncoloured vertex whose
    /// priority beats every uncoloured neighbour's takes the smallest colour none of its
    /// neighbours has. A round reads the previous round's colours and writes a new array, so
    /// the colours depend on the graph and the seed alone: the same on the CPU at any thread
    /// count and on a GPU. At most `Δ + 1` colours (`Δ` the largest degree), in expected
    /// `O(log n / log log n)` rounds; each round colours at least the uncoloured vertex of
    /// highest priority, so the loop ends.
    ///
    /// The rounds run two at a time in a [`capture_while`](crate::capture_while) loop on a
    /// device flag (outside a capture: a read-back of the flag per two rounds); `order` and
    /// `offsets` come from a stable radix sort by colour, and one read-back of the last colour
    /// sizes `offsets`.
    ///
    /// # Errors
    /// [`Error::Capture`] inside a capture (it allocates and reads back); a fault of the
    /// queued work (a bad adjacency's).
    pub fn new(g: &Adjacency, seed: u32) -> Result<Self> {
        let (n, dev) = (g.n, g.device().clone());
        let colors = Array::<i32>::zeros(n, &dev)?;
        if n == 0 {
            return Ok(Coloring {
                colors,
                order: Array::zeros(0, &dev)?,
                offsets: Array::zeros(1, &dev)?,
            });
        }
        colors.fill(-1)?;
        let other = Array::<i32>::zeros(n, &dev)?;
        let flag = Array::<i32>::zeros(1, &dev)?;
        flag.fill(1)?;
        let round = |prev: &Array<i32>, next: &Array<i32>, clear: bool| Round {
            offsets: g.offsets.device_address(),
            columns: g.columns.device_address(),
            prev: prev.device_address(),
            next: next.device_address(),
            flag: flag.device_address(),
            n: n as i32,
            cap: g.columns.len() as i32,
            seed,
            clear: clear as i32,
        };
        // Two rounds a pass, so the colours end in `colors`: the first clears the flag, the
        // second sets it while a vertex is left.
        crate::graph::capture_while(&flag, || {
            run(&dev, &round(&colors, &other, true))?;
            run(&dev, &round(&other, &colors, false))
        })?;
        let keys = Array::<u32>::zeros(n, &dev)?;
        let order = Array::<i32>::zeros(n, &dev)?;
        let sort = |offsets: u64, ncolors: i32| Sort::<true> {
            colors: colors.device_address(),
            keys: keys.device_address(),
            order: order.device_address(),
            offsets,
            n: n as i32,
            ncolors,
        };
        run(&dev, &sort(0, 0))?;
        // A colour is at most the largest degree, below the adjacency's capacity.
        radix_sort_pairs(&keys, &order, n, Some(key_bits(g.columns.len() as u64)))?;
        let last = keys.view(n - 1..n)?.to_vec()?[0];
        let ncolors = i32::try_from(last)
            .ok()
            .filter(|c| (*c as usize) < n)
            .ok_or_else(|| {
                Error::invalid(format!(
                    "sparse::Coloring::new: internal: the rounds ended with colour {last}"
                ))
            })?
            + 1;
        let offsets = Array::<i32>::zeros(ncolors as usize + 1, &dev)?;
        run(
            &dev,
            &sort(offsets.device_address(), ncolors).step::<false>(),
        )?;
        Ok(Coloring {
            colors,
            order,
            offsets,
        })
    }

    /// The number of colours.
    pub fn count(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Vertices coloured (the graph's).
    pub fn len(&self) -> usize {
        self.colors.len()
    }

    /// Whether the graph had no vertex.
    pub fn is_empty(&self) -> bool {
        self.colors.is_empty()
    }

    /// Each colour's vertex range in `order` (`offsets` read back): colour `c`'s vertices are
    /// `order[r[c].clone()]`. For launching a kernel per colour over its vertices.
    ///
    /// # Errors
    /// A fault of the queued work, or a read-back inside a capture.
    pub fn ranges(&self) -> Result<Vec<std::ops::Range<usize>>> {
        let o = self.offsets.to_vec()?;
        Ok(o.windows(2)
            .map(|w| w[0].max(0) as usize..w[1].max(w[0]).max(0) as usize)
            .collect())
    }
}
