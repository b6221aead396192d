//! A model of the memory traffic a frame's rays make when they read a structure's device arrays:
//! how many bytes each ray asks for, how many cache lines it spans, how much of the structure the
//! frame touches, and how many bytes must come from DRAM behind an L2 cache of 4 to 72 MiB. The
//! RBVH trades exactness for a structure several times smaller than the exact BVH; this model
//! predicts where that pays, on GPUs whose L2 holds the small structure but not the big one.
//!
//! # Input
//!
//! The CPU reference tracers report every read a ray makes of the structure's arrays as a
//! [`Read`] — array, byte offset, byte count — in the device buffers' layout and in the order the
//! shader makes them (`crate::probe`). The caller gives [`TrafficModel::ray`] each ray's reads,
//! ray after ray, in the order the GPU would process them: screen tiles ([`tile_order`]).
//!
//! # Address space
//!
//! Each array of [`Array::ALL`] is placed, in that order, at a base address: one after the other,
//! each base aligned up to [`ARRAY_ALIGN`] (4096 bytes), as separate device allocations would be;
//! the sizes are the caller's, 0 for an array the structure does not have, and a read past its
//! array's size is an error. A read's address is its array's base plus its offset, so equal
//! offsets in different arrays never share a line. A read of `bytes` bytes touches every line it
//! overlaps: a read may straddle two lines.
//!
//! # Figures ([`Traffic`])
//!
//! - **Per ray**, as means over the frame's rays: reads, bytes requested (the sum of the reads'
//!   sizes), and distinct lines touched at 64 bytes (AMD GCN's cache lines) and at
//!   128 bytes (the L1 and L2 lines of NVIDIA's and AMD RDNA's GPUs). A line read twice by one
//!   ray counts once; by two rays, once for each.
//! - **Working set**: the distinct bytes the whole frame touches, at 4-byte word granularity (every
//!   read of this project is 4-byte aligned and a multiple of 4 bytes; other reads are rounded
//!   outward to whole words), next to the structure's total size. In the model, a working set
//!   that fits in a cache costs only its compulsory misses: one per distinct line.
//! - **DRAM traffic**: one least-recently-used cache per capacity ([`CACHE_SIZES`]), fully
//!   associative, with lines of [`DRAM_LINE`] bytes by default, empty at the start of the frame.
//!   Every line a read touches is one access; a miss fetches the whole line from DRAM. Per
//!   capacity: DRAM bytes per ray (misses × line size / rays) and the miss rate (misses /
//!   accesses).
//!
//! # Assumptions and limits
//!
//! The model ranks structures by the traffic their access patterns imply; it does not predict a
//! GPU's absolute timings. Its idealisations:
//!
//! - **Fully associative LRU.** Real L2s are set-associative, index sets through an address hash
//!   and replace by approximations of LRU; conflict misses, which the model has none of, raise
//!   their miss rate.
//! - **One ray at a time, in tile order.** A GPU runs many warps at once, on every multiprocessor,
//!   and their accesses interleave in the shared L2; every tile in flight competes for the cache,
//!   so each gets a smaller share than the whole of it. The model is therefore optimistic, most of
//!   all for a cache close to the working set's size, where that competition decides between hits
//!   and misses; for a cache much larger or much smaller than the working set, the order matters
//!   little.
//! - **Whole lines.** A miss fetches the whole line; NVIDIA's L2 fetches 32-byte sectors, so for
//!   scattered 4-byte reads (height-field texels) real DRAM traffic can be lower.
//! - **Only the structure's reads.** Writes (hits, counters, stack spills), the ray and hit
//!   buffers, and the L1 caches in front of the L2 are not modelled. An L1 would catch some of
//!   the reuse within a ray, which lowers the L2's accesses more than its misses: what it
//!   catches is recent reuse, which the L2 would have hit too.
//!
//! # Implementation
//!
//! All capacities come from one pass over one recency stack (Mattson et al., "Evaluation
//! techniques for storage hierarchies", 1970): a line is in the LRU cache of `C` lines exactly
//! when it is among the `C` most recently used, so one list in recency order, with a marker at
//! each capacity's boundary, answers for every capacity at once. Each access costs O(number of
//! capacities) pointer steps. Memory: 4 bytes per line of the address space (line ids), 12 bytes
//! per distinct line touched, and one bit per 4-byte word of the address space (working set).

use crate::probe::{Array, Read};
use crate::{Error, Result};

/// Capacities of the modelled caches, bytes: 4, 32 and 72 MiB, from a small or older GPU's L2 to
/// an RTX 4090's (an H100's holds 50 MB, an A100's 40 MB).
pub const CACHE_SIZES: [u64; 3] = [4 << 20, 32 << 20, 72 << 20];

/// Line size of the modelled caches, bytes: the L2 line of NVIDIA's and AMD RDNA's GPUs.
pub const DRAM_LINE: u32 = 128;

/// Alignment of each array's base address, bytes: separate device allocations start at least a
/// page apart.
pub const ARRAY_ALIGN: u64 = 4096;

/// End of the recency list, a marker not placed yet, or a line never touched.
const NIL: u32 = u32::MAX;

/// What the model predicts for one frame of rays through one structure.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Traffic {
    /// Rays fed to the model.
    pub rays: u64,
    /// The structure's arrays, bytes, in total.
    pub structure_bytes: u64,
    /// Distinct bytes the frame reads, counted in 4-byte words.
    pub working_set_bytes: u64,
    /// Mean reads per ray.
    pub reads_per_ray: f64,
    /// Mean bytes requested per ray: the sum of its reads' sizes.
    pub bytes_per_ray: f64,
    /// Mean distinct 64-byte lines per ray.
    pub lines64_per_ray: f64,
    /// Mean distinct 128-byte lines per ray.
    pub lines128_per_ray: f64,
    /// One entry per modelled cache, in the order [`TrafficModel::new`] was given them.
    pub caches: Vec<CacheTraffic>,
}

/// DRAM traffic behind one modelled cache.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CacheTraffic {
    /// The cache's capacity, bytes.
    pub capacity_bytes: u64,
    /// Its line size, bytes: what each miss fetches.
    pub line_bytes: u32,
    /// Misses over line accesses (0 when there were none).
    pub miss_rate: f64,
    /// Mean bytes fetched from DRAM per ray: misses × line size / rays.
    pub dram_bytes_per_ray: f64,
}

/// Feeds a frame's reads, ray by ray, to the per-ray counts, the working set and every modelled
/// cache at once; [`TrafficModel::report`] gives the figures. See the module documentation for
/// the model.
pub struct TrafficModel {
    array_bytes: [u64; Array::COUNT],
    bases: [u64; Array::COUNT],
    line_bytes: u32,
    line_shift: u32,
    /// Recency-stack id of each line of the address space (address >> `line_shift`), [`NIL`] for
    /// one never touched: dense ids keep the stack as small as the working set.
    line_ids: Vec<u32>,
    stack: RecencyStack,
    /// The caches' capacities in the caller's order, and each one's index in `stack.capacities`.
    caches: Vec<(u64, usize)>,
    /// One bit per 4-byte word of the address space: read by some ray of the frame.
    touched_words: Vec<u64>,
    working_set_words: u64,
    /// The current ray's 64-byte line numbers: a buffer kept between rays.
    ray_lines: Vec<u64>,
    rays: u64,
    reads: u64,
    bytes: u64,
    lines64: u64,
    lines128: u64,
}

impl TrafficModel {
    /// A model of a structure whose arrays hold `array_bytes` bytes ([`Array::ALL`] order, 0 for
    /// an absent array), behind one LRU cache per capacity in `caches` (bytes; [`CACHE_SIZES`]),
    /// each with lines of `line` bytes ([`DRAM_LINE`]).
    ///
    /// Errors when `line` is not a power of two, when a cache holds less than one line, or when
    /// the arrays are too large to model (more than 2³² − 1 lines).
    pub fn new(
        array_bytes: [u64; Array::COUNT],
        caches: &[u64],
        line: u32,
    ) -> Result<TrafficModel> {
        if !line.is_power_of_two() {
            return Err(Error::param(
                "line",
                format!("{line} bytes is not a power of two"),
            ));
        }
        let (bases, end) = layout(&array_bytes).ok_or_else(|| {
            Error::param(
                "array_bytes",
                format!("{array_bytes:?} overflows a 64-bit address space"),
            )
        })?;
        let lines = end.div_ceil(u64::from(line));
        if lines >= u64::from(NIL) {
            return Err(Error::param(
                "array_bytes",
                format!("{end} bytes make {lines} lines of {line} bytes: too many for 32-bit ids"),
            ));
        }
        if let Some(small) = caches.iter().find(|&&c| c < u64::from(line)) {
            return Err(Error::param(
                "caches",
                format!("a cache of {small} bytes holds no line of {line} bytes"),
            ));
        }
        // A cache larger than the whole address space behaves like one exactly that large; the
        // clamp keeps capacities within the 32-bit ids.
        let in_lines = |capacity: u64| (capacity / u64::from(line)).min(lines.max(1)) as u32;
        let mut ascending: Vec<u32> = caches.iter().map(|&c| in_lines(c)).collect();
        ascending.sort_unstable();
        let caches = caches
            .iter()
            .map(|&c| {
                let rank = ascending.partition_point(|&a| a < in_lines(c));
                (c, rank)
            })
            .collect();
        let words = end.div_ceil(4);
        Ok(TrafficModel {
            array_bytes,
            bases,
            line_bytes: line,
            line_shift: line.trailing_zeros(),
            line_ids: if ascending.is_empty() {
                Vec::new()
            } else {
                vec![NIL; lines as usize]
            },
            stack: RecencyStack::new(ascending),
            caches,
            touched_words: vec![0; words.div_ceil(64) as usize],
            working_set_words: 0,
            ray_lines: Vec::new(),
            rays: 0,
            reads: 0,
            bytes: 0,
            lines64: 0,
            lines128: 0,
        })
    }

    /// Feeds one ray's reads, in the order it made them; rays go in processing order (screen
    /// tiles, [`tile_order`]). A ray without reads counts as a ray that read nothing.
    ///
    /// Errors, leaving the model as it was, when a read ends past its array's size.
    pub fn ray(&mut self, reads: &[Read]) -> Result<()> {
        for read in reads {
            let size = self.array_bytes[read.array as usize];
            if read
                .offset
                .checked_add(u64::from(read.bytes))
                .is_none_or(|end| end > size)
            {
                return Err(Error::param(
                    "read",
                    format!(
                        "{} bytes at offset {} of {:?} end past the array's {size} bytes",
                        read.bytes, read.offset, read.array
                    ),
                ));
            }
        }
        self.ray_lines.clear();
        let caching = !self.stack.capacities.is_empty();
        for read in reads {
            self.reads += 1;
            self.bytes += u64::from(read.bytes);
            if read.bytes == 0 {
                continue;
            }
            let start = self.bases[read.array as usize] + read.offset;
            let last = start + u64::from(read.bytes) - 1;
            self.ray_lines.extend((start >> 6)..=(last >> 6));
            self.working_set_words += set_bits(&mut self.touched_words, start / 4, last / 4 + 1);
            if caching {
                for line in (start >> self.line_shift)..=(last >> self.line_shift) {
                    let id = &mut self.line_ids[line as usize];
                    if *id == NIL {
                        *id = self.stack.add_line();
                    }
                    self.stack.access(*id);
                }
            }
        }
        self.ray_lines.sort_unstable();
        self.ray_lines.dedup();
        self.lines64 += self.ray_lines.len() as u64;
        // Sorted 64-byte lines group by their 128-byte line: count the groups.
        self.lines128 += self.ray_lines.chunk_by(|a, b| a >> 1 == b >> 1).count() as u64;
        self.rays += 1;
        Ok(())
    }

    /// The figures for the rays fed so far (zeros before the first).
    pub fn report(&self) -> Traffic {
        let per_ray = |total: u64| {
            if self.rays == 0 {
                0.0
            } else {
                total as f64 / self.rays as f64
            }
        };
        let accesses: u64 = self.stack.bands.iter().sum();
        let caches = self
            .caches
            .iter()
            .map(|&(capacity, rank)| {
                // Bands beyond the cache's own are the accesses it misses.
                let misses: u64 = self.stack.bands[rank + 1..].iter().sum();
                CacheTraffic {
                    capacity_bytes: capacity,
                    line_bytes: self.line_bytes,
                    miss_rate: if accesses == 0 {
                        0.0
                    } else {
                        misses as f64 / accesses as f64
                    },
                    dram_bytes_per_ray: per_ray(misses * u64::from(self.line_bytes)),
                }
            })
            .collect();
        Traffic {
            rays: self.rays,
            structure_bytes: self.array_bytes.iter().sum(),
            working_set_bytes: self.working_set_words * 4,
            reads_per_ray: per_ray(self.reads),
            bytes_per_ray: per_ray(self.bytes),
            lines64_per_ray: per_ray(self.lines64),
            lines128_per_ray: per_ray(self.lines128),
            caches,
        }
    }
}

/// Pixel indices (row-major: `y * width + x`) ordered tile by tile: tiles of `tile` × `tile`
/// pixels in row-major order, pixels within a tile row-major, partial tiles at the right and
/// bottom edges included. `tile` = 8 makes each tile one 64-thread workgroup of 8 × 8 pixels.
/// (The trace shaders take rays in their buffer's order, 64 per workgroup, so a workgroup is such
/// a tile only when the rays are laid out in this order; with row-major rays it is 64 pixels of one
/// row.) `tile` = 0 is taken as 1: plain row-major order. `width × height` must fit in `u32`, as it
/// does for every image the project accepts (16384² at most).
pub fn tile_order(width: u32, height: u32, tile: u32) -> Vec<u32> {
    let tile = tile.max(1);
    let mut order = Vec::with_capacity(width as usize * height as usize);
    for tile_y in (0..height).step_by(tile as usize) {
        for tile_x in (0..width).step_by(tile as usize) {
            for y in tile_y..tile_y.saturating_add(tile).min(height) {
                order.extend(
                    (tile_x..tile_x.saturating_add(tile).min(width)).map(|x| y * width + x),
                );
            }
        }
    }
    order
}

/// The base address of each array ([`Array::ALL`] order) and the end of the last one: arrays one
/// after the other, each base aligned up to [`ARRAY_ALIGN`]. `None` on overflow.
fn layout(array_bytes: &[u64; Array::COUNT]) -> Option<([u64; Array::COUNT], u64)> {
    let mut bases = [0; Array::COUNT];
    let mut end = 0u64;
    for array in Array::ALL {
        let base = end.checked_next_multiple_of(ARRAY_ALIGN)?;
        bases[array as usize] = base;
        end = base.checked_add(array_bytes[array as usize])?;
    }
    Some((bases, end))
}

/// Sets bits `lo..hi` of `bits`; returns how many were clear.
fn set_bits(bits: &mut [u64], lo: u64, hi: u64) -> u64 {
    let mut newly_set = 0;
    let mut i = lo;
    while i < hi {
        let bit = i % 64;
        let n = (hi - i).min(64 - bit);
        let mask = if n == 64 {
            u64::MAX
        } else {
            ((1 << n) - 1) << bit
        };
        let word = &mut bits[(i / 64) as usize];
        newly_set += u64::from((mask & !*word).count_ones());
        *word |= mask;
        i += n;
    }
    newly_set
}

/// A line's place in the recency stack.
#[derive(Clone, Copy)]
struct Node {
    /// The next more recently used line, [`NIL`] at the head.
    prev: u32,
    /// The next less recently used line, [`NIL`] at the tail.
    next: u32,
    /// The line's band: how many caches it is *not* in. A line at stack position `p` (0 = most
    /// recent) is in band `b` when `capacities[b - 1] <= p < capacities[b]`; band
    /// `capacities.len()` is "in no cache" (never touched, or evicted from the largest).
    band: u32,
}

/// Every capacity's fully associative LRU cache at once, as one recency stack of the lines the
/// largest cache holds, most recent first. A line is in the cache of `C` lines when its position
/// is below `C`, so an access hits every cache above the line's band and misses the others; the
/// markers at the band boundaries move by one line per access, which keeps each access's cost
/// proportional to the number of capacities, not to their size.
struct RecencyStack {
    /// Capacities in lines, ascending; at least 1.
    capacities: Vec<u32>,
    /// By line id.
    nodes: Vec<Node>,
    head: u32,
    tail: u32,
    /// Lines in the stack: at most the largest capacity.
    len: u32,
    /// `markers[k]`: the line at position `capacities[k] - 1`, the last one cache `k` holds;
    /// [`NIL`] while the stack is shorter.
    markers: Vec<u32>,
    /// `bands[b]`: accesses to a line in band `b`, so cache `k` missed `bands[k + 1..]`.
    bands: Vec<u64>,
}

impl RecencyStack {
    fn new(capacities: Vec<u32>) -> RecencyStack {
        let caches = capacities.len();
        RecencyStack {
            capacities,
            nodes: Vec::new(),
            head: NIL,
            tail: NIL,
            len: 0,
            markers: vec![NIL; caches],
            bands: vec![0; caches + 1],
        }
    }

    /// A new id, for a line in no cache yet. The caller keeps ids below [`NIL`].
    fn add_line(&mut self) -> u32 {
        let id = self.nodes.len() as u32;
        self.nodes.push(Node {
            prev: NIL,
            next: NIL,
            band: self.capacities.len() as u32,
        });
        id
    }

    /// One access to line `x`: counted in its band, then moved to the head. Lines between the
    /// head and `x`'s old place move one position down, so the last line of each cache `x` was
    /// not in crosses into the next band, and the cache's marker moves to the line before it.
    fn access(&mut self, x: u32) {
        let outside = self.capacities.len();
        let band = self.nodes[x as usize].band as usize;
        self.bands[band] += 1;
        if self.head == x {
            return;
        }
        let len_before = self.len;
        if band < outside {
            // Not the head, so it has a predecessor, which takes its place at any boundary.
            let prev = self.nodes[x as usize].prev;
            self.unlink(x);
            for marker in &mut self.markers[band..] {
                if *marker == x {
                    *marker = prev;
                }
            }
        }
        self.push_front(x);
        self.nodes[x as usize].band = 0;
        for k in 0..band {
            let marker = self.markers[k];
            if marker != NIL {
                // `x` is the head now, so a marker that was at the old head steps onto `x`.
                let node = &mut self.nodes[marker as usize];
                node.band += 1;
                self.markers[k] = node.prev;
            } else if len_before + 1 == self.capacities[k] {
                // A new line has just filled this cache.
                self.markers[k] = self.tail;
            }
        }
        if band == outside {
            if len_before == self.capacities[outside - 1] {
                // The largest cache was full: its last line, now past it, is evicted.
                let evicted = self.tail;
                self.tail = self.nodes[evicted as usize].prev;
                self.nodes[self.tail as usize].next = NIL;
                self.nodes[evicted as usize].prev = NIL;
            } else {
                self.len += 1;
            }
        }
    }

    /// Takes `x`, which is in the stack but not its head, out of the list.
    fn unlink(&mut self, x: u32) {
        let Node { prev, next, .. } = self.nodes[x as usize];
        self.nodes[prev as usize].next = next;
        if next == NIL {
            self.tail = prev;
        } else {
            self.nodes[next as usize].prev = prev;
        }
    }

    fn push_front(&mut self, x: u32) {
        let old_head = self.head;
        let node = &mut self.nodes[x as usize];
        node.prev = NIL;
        node.next = old_head;
        if old_head == NIL {
            self.tail = x;
        } else {
            self.nodes[old_head as usize].prev = x;
        }
        self.head = x;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Arrays of 1 MiB nodes and 1 MiB atlas words, the others absent.
    const ARRAYS: [u64; Array::COUNT] = [1 << 20, 0, 0, 1 << 20, 0, 0, 0];

    fn node(index: u64) -> Read {
        Read {
            array: Array::Nodes,
            offset: index * 64,
            bytes: 64,
        }
    }

    fn read(array: Array, offset: u64, bytes: u32) -> Read {
        Read {
            array,
            offset,
            bytes,
        }
    }

    /// A 4-byte read in line `line` of the node array, for lines of `DRAM_LINE` bytes.
    fn line(line: u64) -> Read {
        read(Array::Nodes, line * u64::from(DRAM_LINE), 4)
    }

    fn lines(n: u64) -> u64 {
        n * u64::from(DRAM_LINE)
    }

    #[test]
    fn cyclic_access_fits_or_thrashes() {
        let (n, k) = (10, 5);
        let caches = [lines(n), lines(n - 1), lines(4 * n)];
        let mut model = TrafficModel::new(ARRAYS, &caches, DRAM_LINE).unwrap();
        for _ in 0..k {
            for i in 0..n {
                model.ray(&[line(i)]).unwrap();
            }
        }
        let report = model.report();
        let accesses = (n * k) as f64;
        let line = f64::from(DRAM_LINE);
        // Capacity ≥ N: compulsory misses only.
        for cache in [&report.caches[0], &report.caches[2]] {
            assert_eq!(cache.miss_rate, n as f64 / accesses);
            assert_eq!(cache.dram_bytes_per_ray, n as f64 * line / accesses);
        }
        // One line short: LRU evicts each line just before it comes back, so every access misses.
        assert_eq!(report.caches[1].miss_rate, 1.0);
        assert_eq!(report.caches[1].dram_bytes_per_ray, line);
        assert_eq!(report.caches[1].capacity_bytes, caches[1]);
        assert_eq!(report.caches[1].line_bytes, DRAM_LINE);
    }

    #[test]
    fn eviction_order_matters() {
        // Two lines, A B A C B: C evicts B (A was used more recently), so B misses again.
        let mut model = TrafficModel::new(ARRAYS, &[lines(2), lines(3)], DRAM_LINE).unwrap();
        let (a, b, c) = (line(0), line(7), line(3));
        model.ray(&[a, b, a, c, b]).unwrap();
        let report = model.report();
        assert_eq!(report.caches[0].dram_bytes_per_ray, 4.0 * 128.0);
        assert_eq!(report.caches[0].miss_rate, 4.0 / 5.0);
        assert_eq!(report.caches[1].miss_rate, 3.0 / 5.0);
        // Per ray: the same misses spread over the rays.
        let mut model = TrafficModel::new(ARRAYS, &[lines(2)], DRAM_LINE).unwrap();
        for r in [a, b, a, c, b] {
            model.ray(&[r]).unwrap();
        }
        assert_eq!(
            model.report().caches[0].dram_bytes_per_ray,
            4.0 * 128.0 / 5.0
        );
    }

    #[test]
    fn reads_count_every_line_they_overlap() {
        let lines_of = |r: Read| {
            let mut model = TrafficModel::new(ARRAYS, &[], DRAM_LINE).unwrap();
            model.ray(&[r]).unwrap();
            let report = model.report();
            (report.lines64_per_ray, report.lines128_per_ray)
        };
        // Straddles 64 but not 128.
        assert_eq!(lines_of(read(Array::Nodes, 60, 8)), (2.0, 1.0));
        // Straddles both.
        assert_eq!(lines_of(read(Array::Nodes, 124, 8)), (2.0, 2.0));
        // A 64-byte read at a 64-aligned offset.
        assert_eq!(lines_of(node(1)), (1.0, 1.0));
        // A straddling read is two cache accesses.
        let mut model = TrafficModel::new(ARRAYS, &[lines(4)], DRAM_LINE).unwrap();
        model.ray(&[read(Array::Nodes, 124, 8)]).unwrap();
        assert_eq!(model.report().caches[0].dram_bytes_per_ray, 2.0 * 128.0);
    }

    #[test]
    fn arrays_do_not_alias() {
        let arrays = [100, 5000, 0, 10, 0, 1, 64];
        let (bases, end) = layout(&arrays).unwrap();
        assert_eq!(bases, [0, 4096, 12288, 12288, 16384, 16384, 20480]);
        assert_eq!(end, 20544);
        assert!(bases.iter().all(|b| b % ARRAY_ALIGN == 0));
        let mut model = TrafficModel::new(arrays, &[lines(16)], DRAM_LINE).unwrap();
        let same_offset = [
            read(Array::Nodes, 0, 4),
            read(Array::Triangles, 0, 4),
            read(Array::Atlas, 0, 4),
            read(Array::LodColumns, 0, 1),
        ];
        model.ray(&same_offset).unwrap();
        let report = model.report();
        assert_eq!(report.lines64_per_ray, 4.0);
        assert_eq!(report.lines128_per_ray, 4.0);
        assert_eq!(report.working_set_bytes, 16);
        assert_eq!(report.caches[0].miss_rate, 1.0);
    }

    #[test]
    fn working_set_counts_each_word_once() {
        let mut model = TrafficModel::new(ARRAYS, &[], DRAM_LINE).unwrap();
        model
            .ray(&[read(Array::Nodes, 0, 64), read(Array::Nodes, 32, 64)])
            .unwrap();
        model.ray(&[read(Array::Nodes, 64, 64)]).unwrap();
        // Bytes 0..128, and an unaligned read of words 1000..1002 rounded outward.
        model.ray(&[read(Array::Atlas, 4002, 5)]).unwrap();
        let report = model.report();
        assert_eq!(report.working_set_bytes, 128 + 8);
        assert_eq!(report.structure_bytes, 2 << 20);
        assert_eq!(report.bytes_per_ray, (64.0 + 64.0 + 64.0 + 5.0) / 3.0);
        assert_eq!(report.reads_per_ray, 4.0 / 3.0);
    }

    #[test]
    fn reuse_counts_once_per_ray() {
        let mut model = TrafficModel::new(ARRAYS, &[lines(4)], DRAM_LINE).unwrap();
        model.ray(&[node(0), node(1), node(0)]).unwrap();
        let report = model.report();
        assert_eq!(report.reads_per_ray, 3.0);
        assert_eq!(report.bytes_per_ray, 192.0);
        assert_eq!(report.lines64_per_ray, 2.0);
        assert_eq!(report.lines128_per_ray, 1.0);
        // Across rays, the same lines count again.
        model.ray(&[node(0), node(1)]).unwrap();
        let report = model.report();
        assert_eq!(report.lines64_per_ray, 2.0);
        assert_eq!(report.lines128_per_ray, 1.0);
        assert_eq!(report.working_set_bytes, 128);
        // One compulsory miss among five accesses.
        assert_eq!(report.caches[0].miss_rate, 1.0 / 5.0);
    }

    #[test]
    fn agrees_with_a_naive_lru() {
        let capacities = [1, 3, 3, 7, 20, 5, 60];
        let caches: Vec<u64> = capacities.iter().map(|&c| lines(c)).collect();
        let mut model = TrafficModel::new(ARRAYS, &caches, DRAM_LINE).unwrap();
        let mut naive: Vec<Vec<u64>> = vec![Vec::new(); capacities.len()];
        let mut misses = vec![0u64; capacities.len()];
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let accesses = 20_000;
        for _ in 0..accesses {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            // Mostly a few hot lines, sometimes any of 80.
            let l = if state % 4 == 0 {
                (state >> 8) % 80
            } else {
                (state >> 8) % 12
            };
            model.ray(&[line(l)]).unwrap();
            for ((cache, &capacity), missed) in naive.iter_mut().zip(&capacities).zip(&mut misses) {
                match cache.iter().position(|&x| x == l) {
                    Some(at) => {
                        cache.remove(at);
                    }
                    None => {
                        *missed += 1;
                        if cache.len() == capacity as usize {
                            cache.pop();
                        }
                    }
                }
                cache.insert(0, l);
            }
        }
        let report = model.report();
        for (cache, missed) in report.caches.iter().zip(misses) {
            assert_eq!(cache.miss_rate, missed as f64 / f64::from(accesses));
        }
    }

    #[test]
    fn out_of_bounds_reads_are_rejected() {
        let mut model = TrafficModel::new(ARRAYS, &[lines(4)], DRAM_LINE).unwrap();
        model.ray(&[node(0)]).unwrap();
        let before = model.report();
        assert!(model
            .ray(&[node(1), read(Array::Nodes, (1 << 20) - 4, 8)])
            .is_err());
        assert!(model.ray(&[read(Array::Triangles, 0, 4)]).is_err());
        assert!(model.ray(&[read(Array::Atlas, u64::MAX, 4)]).is_err());
        assert_eq!(model.report(), before);
        assert!(model.ray(&[read(Array::Nodes, (1 << 20) - 4, 4)]).is_ok());
    }

    #[test]
    fn invalid_parameters_are_rejected() {
        assert!(TrafficModel::new(ARRAYS, &CACHE_SIZES, 96).is_err());
        assert!(TrafficModel::new(ARRAYS, &CACHE_SIZES, 0).is_err());
        assert!(TrafficModel::new(ARRAYS, &[64], DRAM_LINE).is_err());
        assert!(TrafficModel::new([u64::MAX, 1, 0, 0, 0, 0, 0], &[], DRAM_LINE).is_err());
        // A cache larger than the structure is fine: it holds everything.
        let mut model = TrafficModel::new(ARRAYS, &[u64::MAX], DRAM_LINE).unwrap();
        model.ray(&[node(0), node(2), node(0)]).unwrap();
        assert_eq!(model.report().caches[0].miss_rate, 2.0 / 3.0);
    }

    #[test]
    fn no_rays_report_zeros() {
        let report = TrafficModel::new(ARRAYS, &CACHE_SIZES, DRAM_LINE)
            .unwrap()
            .report();
        assert_eq!(report.rays, 0);
        assert_eq!(report.reads_per_ray, 0.0);
        assert_eq!(report.caches.len(), 3);
        assert!(report
            .caches
            .iter()
            .all(|c| c.miss_rate == 0.0 && c.dram_bytes_per_ray == 0.0));
    }

    #[test]
    fn tile_order_covers_tiles_in_turn() {
        assert_eq!(tile_order(3, 2, 2), [0, 1, 3, 4, 2, 5]);
        assert_eq!(tile_order(3, 2, 0), [0, 1, 2, 3, 4, 5]);
        assert_eq!(tile_order(0, 5, 8), Vec::<u32>::new());
        for (width, height, tile) in [(13, 7, 8), (9, 9, 2), (5, 3, 7), (16, 16, 8)] {
            let mut order = tile_order(width, height, tile);
            order.sort_unstable();
            assert_eq!(order, (0..width * height).collect::<Vec<_>>());
        }
        // Tile 8: the first 64 pixels are the top-left 8 × 8 block.
        let order = tile_order(20, 20, 8);
        assert!(order[..64].iter().all(|&p| p % 20 < 8 && p / 20 < 8));
    }
}
