//! What a traversal reports about its own work, in the same terms on the GPU and the CPU twins:
//! per-ray [`RayCounters`] (counted by the trace shaders when counting is specialised on, in the
//! two records of `glsl/trace_io.glsl`; `glsl/common.glsl`'s `RbvhCounters` where an engine
//! counts) and the reads a ray makes of the structure's device arrays ([`Read`], reported to a
//! [`Probe`] by the CPU twins), from which `crate::bench::traffic` models memory traffic.
//!
//! The counters are how the "where a ray's work goes" tables of docs/ray-work.md are made, and how a speed
//! difference is explained rather than only measured: the exact BVH's and the RBVH's steps are
//! counted alike (an inner node is an inner node in both).

use bytemuck::{Pod, Zeroable};

/// One ray's work, counted the same way by the device (`glsl/trace_io.glsl`'s records) and
/// by the CPU twins (`Bvh::closest_hit`, `Rbvh::closest_hit`), so the two can be compared ray by
/// ray. 40 bytes, 10 words in this order (`tests/layout.rs` checks the trace shaders' two records,
/// the first eight words and the last two, and `tests/glsl_header.rs` the struct an engine
/// counts in).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct RayCounters {
    /// Inner nodes visited (both children's boxes tested).
    pub nodes: u32,
    /// Height-field leaves (and, with level of detail, chosen coarse nodes) handed to the march.
    pub leaves: u32,
    /// Of those, the ones whose tile box the ray crosses, so that a walk starts.
    pub walks: u32,
    /// Cells stepped into and handed to the cell test (with level of detail, columns too).
    pub cells: u32,
    /// Cells past the cheap height rejection: those whose triangles were tested.
    pub cells_tested: u32,
    /// Block jumps of the device march (`src/rbvh/ranges.rs`): blocks crossed without a cell test.
    pub jumps: u32,
    /// Triangle leaves tested (the exact BVH's leaves, the RBVH's hybrid leaves).
    pub triangle_leaves: u32,
    /// Triangles tested in triangle leaves (height-field cells count in `cells`).
    pub triangles: u32,
    /// Instances entered (a two-level structure's top-level leaves; 0 in every other).
    pub instances: u32,
    /// Of `nodes`, those a two-level structure's ray visited outside any instance (0 in every
    /// other): its top level's, and those of the mesh the top level grafts
    /// ([`crate::bvh::GRAFTED`]); the rest were visited in the instances' meshes.
    pub top_nodes: u32,
}
const _: () = assert!(std::mem::size_of::<RayCounters>() == 40);

impl RayCounters {
    /// The heat map's "steps": inner nodes + triangles tested + cells visited.
    pub fn steps(&self) -> u32 {
        self.nodes
            .saturating_add(self.triangles)
            .saturating_add(self.cells)
    }
}

/// The means of many rays' counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeanCounters {
    /// Inner nodes visited per ray ([`RayCounters::nodes`]).
    pub nodes: f64,
    /// Height-field leaves handed to the march per ray ([`RayCounters::leaves`]).
    pub leaves: f64,
    /// Walks started per ray ([`RayCounters::walks`]).
    pub walks: f64,
    /// Cells stepped into per ray ([`RayCounters::cells`]).
    pub cells: f64,
    /// Cells whose triangles were tested, per ray ([`RayCounters::cells_tested`]).
    pub cells_tested: f64,
    /// Block jumps per ray ([`RayCounters::jumps`]).
    pub jumps: f64,
    /// Triangle leaves tested per ray ([`RayCounters::triangle_leaves`]).
    pub triangle_leaves: f64,
    /// Triangles tested in triangle leaves per ray ([`RayCounters::triangles`]).
    pub triangles: f64,
    /// Instances entered per ray ([`RayCounters::instances`]; absent from records made before
    /// two-level structures, read as 0).
    #[serde(default)]
    pub instances: f64,
    /// Inner nodes visited outside any instance per ray ([`RayCounters::top_nodes`]: the top
    /// level's and the grafted mesh's; as `instances`).
    #[serde(default)]
    pub top_nodes: f64,
    /// Mean steps ([`RayCounters::steps`]) over the mean of the longest in each group of 8
    /// consecutive rays: how busy an 8-wide SIMD group (lavapipe's, on AVX2) stays when every lane
    /// waits for its slowest. 1 when all rays of a group cost alike.
    pub simd8_utilisation: f64,
}

impl MeanCounters {
    /// Means over `counters` (zeros for none).
    pub fn of(counters: &[RayCounters]) -> MeanCounters {
        if counters.is_empty() {
            return MeanCounters::default();
        }
        let n = counters.len() as f64;
        let mean =
            |f: fn(&RayCounters) -> u32| counters.iter().map(|c| f64::from(f(c))).sum::<f64>() / n;
        let (mut busy, mut total) = (0.0, 0.0);
        for group in counters.chunks(8) {
            let longest = group.iter().map(RayCounters::steps).max().unwrap_or(0);
            busy += group.iter().map(|c| f64::from(c.steps())).sum::<f64>();
            total += f64::from(longest) * group.len() as f64;
        }
        MeanCounters {
            nodes: mean(|c| c.nodes),
            leaves: mean(|c| c.leaves),
            walks: mean(|c| c.walks),
            cells: mean(|c| c.cells),
            cells_tested: mean(|c| c.cells_tested),
            jumps: mean(|c| c.jumps),
            triangle_leaves: mean(|c| c.triangle_leaves),
            triangles: mean(|c| c.triangles),
            instances: mean(|c| c.instances),
            top_nodes: mean(|c| c.top_nodes),
            simd8_utilisation: if total > 0.0 { busy / total } else { 1.0 },
        }
    }
}

/// The device arrays a traversal reads, in the order a tracer binds them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Array {
    /// Inner nodes (`GpuNode`, 48 bytes each).
    Nodes = 0,
    /// Triangles of triangle leaves: the exact BVH's (`GpuTriangle`, 48 bytes each), an RBVH's
    /// indexed (`rbvh::ExactTriangles`: 16-byte slots, then 16-byte vertices).
    Triangles = 1,
    /// Height-field leaf records (`GpuHeightfield`, 64 bytes each).
    Heightfields = 2,
    /// The atlas words (`Atlas::device_words`): height codes, the 8×8 blocks' height ranges, then
    /// with normals the rank directory and the normals of the texels that are not holes.
    Atlas = 3,
    /// Level-of-detail records (`GpuLod`, 48 bytes each).
    LodRecords = 4,
    /// Level-of-detail column words (4 bytes each).
    LodColumns = 5,
    /// Instances of a two-level structure (`GpuInstance`, 64 bytes each).
    Instances = 6,
}

impl Array {
    /// How many arrays there are.
    pub const COUNT: usize = 7;

    /// Every array, in binding order.
    pub const ALL: [Array; Array::COUNT] = [
        Array::Nodes,
        Array::Triangles,
        Array::Heightfields,
        Array::Atlas,
        Array::LodRecords,
        Array::LodColumns,
        Array::Instances,
    ];
}

/// One read a ray makes: `bytes` bytes from byte `offset` of `array`, as the shader reads them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Read {
    /// The device array read.
    pub array: Array,
    /// Byte offset of the read from the start of `array`.
    pub offset: u64,
    /// Bytes read: the size of the record or word the shader loads.
    pub bytes: u32,
}

/// Receives the reads of one traversal, in the order the device makes them. The CPU twins call it
/// where their GLSL twins read memory; the no-op `()` costs nothing.
pub trait Probe {
    /// Whether it records reads at all: where it does not, the twin skips working out reads
    /// that cost it more than the read itself (a hit normal's place among the device's words).
    const RECORDS: bool = true;

    /// Records one read, called in the device's read order.
    fn read(&mut self, read: Read);
}

impl Probe for () {
    const RECORDS: bool = false;

    #[inline(always)]
    fn read(&mut self, _: Read) {}
}

impl Probe for Vec<Read> {
    fn read(&mut self, read: Read) {
        self.push(read);
    }
}

/// What one traversal reports: its [`RayCounters`], and whether it was cut short (the stack
/// overflowed, impossible for a tree no deeper than the stack, or, in corrupt data only, a cycle
/// made it visit more nodes than there are).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraceStats {
    /// The ray's work, up to where it ended.
    pub counters: RayCounters,
    /// True when the traversal was cut short, so its hit is not trustworthy (the device reports
    /// such rays as [`Error::StackOverflow`](crate::Error::StackOverflow)).
    pub overflow: bool,
}

/// The read of element `index` of `array`, whose elements are `T`s read whole.
pub(crate) fn element<T>(array: Array, index: usize) -> Read {
    let size = std::mem::size_of::<T>();
    Read {
        array,
        offset: (index as u64).saturating_mul(size as u64),
        bytes: size as u32,
    }
}
