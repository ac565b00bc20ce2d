//! Building a binary BVH: the builder's vocabulary here (its options, [`BuildPrim`], the
//! bounds it gathers per node), the binned SAH build in [`sah`] (Wald, "On fast
//! Construction of SAH-based Bounding Volume Hierarchies", IEEE Symposium on Interactive Ray
//! Tracing 2007) with its binning (`binning`) and partitioning (`partition`) steps, and the
//! spatial splits of [`BuildQuality::High`] in [`spatial`]. `sah` and `spatial` both depend
//! on this module and `sah` on `spatial`, never the other way round.

mod binning;
mod partition;
pub mod sah;
pub mod spatial;

pub use sah::{build_bvh2, build_bvh2_kinds, build_bvh2_spatial};

use crate::math::{Aabb, Vec3, Vec4};

/// How much effort the builder spends on tree quality.
///
/// Below `High`, every node of at most [`BuildOptions::max_leaf_size`] primitives is a leaf;
/// `High` also weighs splitting those by the SAH. The binary tree is an intermediate for the
/// 8-wide one, whose leaf blocks hold 8 triangles, so splitting such small nodes rarely
/// pays for the binning and sweep each costs (PERFORMANCE.md, "Builder").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BuildQuality {
    /// Fewer bins; for interactive use.
    Fast,
    /// The default trade-off.
    #[default]
    Medium,
    /// More bins, small nodes split by the SAH, and spatial splits where triangles overlap
    /// ([`BuildOptions::spatial_split_budget`]); for final renders and large scenes traced
    /// many times.
    High,
}

impl BuildQuality {
    /// Every effort, least first.
    pub const ALL: [BuildQuality; 3] = [BuildQuality::Fast, BuildQuality::Medium, BuildQuality::High];

    /// Short name: `fast`, `medium`, `high` (what [`BuildQuality::parse`] takes).
    pub fn name(self) -> &'static str {
        match self {
            BuildQuality::Fast => "fast",
            BuildQuality::Medium => "medium",
            BuildQuality::High => "high",
        }
    }

    /// Parses `fast`, `medium` or `high` (any case, surrounding spaces ignored).
    pub fn parse(s: &str) -> Result<BuildQuality, BuildQualityError> {
        let t = s.trim();
        BuildQuality::ALL
            .into_iter()
            .find(|q| q.name().eq_ignore_ascii_case(t))
            .ok_or_else(|| BuildQualityError(s.to_string()))
    }
}

/// A build quality name that is not `fast`, `medium` or `high`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("expected 'fast', 'medium' or 'high', got '{0}'")]
pub struct BuildQualityError(pub String);

impl std::str::FromStr for BuildQuality {
    type Err = BuildQualityError;
    fn from_str(s: &str) -> Result<BuildQuality, BuildQualityError> {
        BuildQuality::parse(s)
    }
}

impl std::fmt::Display for BuildQuality {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The splitting rule.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SplitMethod {
    /// Binned surface area heuristic.
    #[default]
    Sah,
    /// Object median on the largest centroid axis (for comparison only).
    Median,
}

/// Parameters of the BVH build.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildOptions {
    /// Most primitives in a leaf (at least 1). Larger nodes are always split; smaller ones
    /// are leaves below [`BuildQuality::High`].
    pub max_leaf_size: usize,
    /// SAH bins per axis of the largest nodes (clamped to `16 ..= 256`; smaller nodes use
    /// fewer, see [`BuildOptions::bin_count`]); `None` picks from `quality`.
    pub bins: Option<usize>,
    /// Effort knob.
    pub quality: BuildQuality,
    /// At [`BuildQuality::High`], the references spatial splits may add
    /// ([`spatial`]), as a fraction of the primitives; 0 turns them off. Embree's
    /// high-quality builder allows 0.2; the default 0.5 is measured (PERFORMANCE.md, "Spatial
    /// splits").
    pub spatial_split_budget: f32,
    /// Split rule.
    pub split: SplitMethod,
    /// Cost of one traversal step relative to one primitive test.
    pub traversal_cost: f32,
    /// Use the watertight triangle test (Woop, Benthin, Wald 2013) instead of Möller–Trumbore.
    pub watertight: bool,
    /// How the binary tree is collapsed into the 8-wide BVH the kernels traverse (costs and
    /// leaf limits; see [`crate::bvh::CollapseOptions`]).
    pub collapse: crate::bvh::CollapseOptions,
    /// Keep the binary BVH after the collapse, for the scalar reference queries
    /// ([`crate::Scene::intersect1_reference`]) and its statistics. Off by default: the
    /// kernels only traverse the 8-wide BVH, and the binary one costs more than half as much
    /// memory again (PERFORMANCE.md, "Builder").
    pub keep_bvh2: bool,
    /// How the 8-wide BVH stores its triangle blocks: [`crate::bvh::TreeLayout::Default`] (the vectors of
    /// each triangle) or [`crate::bvh::TreeLayout::Compact`] (primitive ids, the blocks built from the
    /// scene store as the kernels reach them: the smallest tree, the same hits).
    pub layout: crate::bvh::TreeLayout,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            max_leaf_size: 4,
            bins: None,
            quality: BuildQuality::Medium,
            spatial_split_budget: 0.5,
            split: SplitMethod::Sah,
            traversal_cost: 1.0,
            watertight: false,
            collapse: crate::bvh::CollapseOptions::default(),
            keep_bvh2: false,
            layout: crate::bvh::TreeLayout::Default,
        }
    }
}

impl BuildOptions {
    /// The most bins per axis a node is binned into. Smaller nodes use fewer: `4 + n/20` for
    /// a node of `n` primitives below [`BuildQuality::High`] (Embree's rule), `max(n, 8)` at
    /// High.
    pub fn bin_count(&self) -> usize {
        let b = self.bins.unwrap_or(match self.quality {
            BuildQuality::Fast => 16,
            BuildQuality::Medium => 32,
            BuildQuality::High => 64,
        });
        b.clamp(16, MAX_BINS)
    }
}

/// The most bins per axis (the bins of [`binning`] are sized for it).
const MAX_BINS: usize = 256;
/// Nodes with more primitives than this bin in parallel chunks (and [`PrimInfo::of_par`]
/// gathers their bounds in chunks of a quarter of it).
const PARALLEL_BIN_THRESHOLD: usize = 1 << 16;

/// One primitive as the builder sees it: its box and its id, as two 16-byte SIMD lanes
/// (`lower.w` holds the id's bits XOR `ID_BITS_BIAS`; `upper.w` is 0). 32 bytes, so two
/// fill a cache line.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct BuildPrim {
    lower: Vec4,
    upper: Vec4,
}
const _: () = assert!(std::mem::size_of::<BuildPrim>() == 32);

/// Makes the id's bits in `lower.w` a normal float (exponent 127 for ids below 2^23): the
/// builder's SIMD arithmetic also runs on the w lane, and a denormal there (a plain small
/// id) costs a microcode assist per operation (PERFORMANCE.md, "Builder").
const ID_BITS_BIAS: u32 = 0x3f80_0000;

impl BuildPrim {
    /// A primitive with box `bounds` (valid and finite) and id `id`.
    #[inline]
    pub fn new(bounds: Aabb, id: u32) -> Self {
        Self { lower: bounds.min.extend(f32::from_bits(id ^ ID_BITS_BIAS)), upper: bounds.max.extend(0.0) }
    }

    /// The id stored in the leaf.
    #[inline]
    pub fn id(&self) -> u32 {
        self.lower.w.to_bits() ^ ID_BITS_BIAS
    }

    /// A reference to primitive `id` with box `bounds` that may be cut `budget` more times
    /// ([`spatial`]).
    #[inline]
    pub(super) fn with_budget(bounds: Aabb, id: u32, budget: u32) -> Self {
        let mut p = Self::new(bounds, id);
        p.set_budget(budget);
        p
    }

    /// How many more times spatial splits may cut this reference (held in `upper.w` as a
    /// small whole float; 0 for a plain build).
    #[inline]
    pub(super) fn budget(&self) -> u32 {
        self.upper.w as u32
    }

    #[inline]
    pub(super) fn set_budget(&mut self, budget: u32) {
        self.upper.w = budget as f32;
    }

    /// The primitive's box.
    #[inline]
    pub fn bounds(&self) -> Aabb {
        Aabb { min: self.lower.truncate(), max: self.upper.truncate() }
    }

    /// Twice the centroid (the builder bins `lower + upper`, saving a multiply; the w lane
    /// is meaningless).
    #[inline]
    fn centroid2(&self) -> Vec4 {
        self.lower + self.upper
    }
}

/// A box in SIMD lanes (the w lanes are meaningless).
#[derive(Clone, Copy, Debug)]
struct Box4 {
    lower: Vec4,
    upper: Vec4,
}

impl Box4 {
    const EMPTY: Box4 = Box4 { lower: Vec4::splat(f32::INFINITY), upper: Vec4::splat(f32::NEG_INFINITY) };

    #[inline]
    fn grow(&mut self, lower: Vec4, upper: Vec4) {
        self.lower = self.lower.min(lower);
        self.upper = self.upper.max(upper);
    }

    #[inline]
    fn union(&self, o: &Box4) -> Box4 {
        Box4 { lower: self.lower.min(o.lower), upper: self.upper.max(o.upper) }
    }

    #[inline]
    fn extent(&self) -> Vec3 {
        (self.upper - self.lower).truncate()
    }

    #[inline]
    fn half_area(&self) -> f32 {
        let e = self.extent().max(Vec3::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    fn aabb(&self) -> Aabb {
        Aabb { min: self.lower.truncate(), max: self.upper.truncate() }
    }
}

/// What a node's builder knows of its primitives before splitting them: their bounds and
/// the bounds of their doubled centroids. Splitting computes both children's right after
/// partitioning, while the primitives are in cache.
#[derive(Clone, Copy, Debug)]
struct PrimInfo {
    bounds: Box4,
    centroids: Box4,
}

impl PrimInfo {
    const EMPTY: PrimInfo = PrimInfo { bounds: Box4::EMPTY, centroids: Box4::EMPTY };

    #[inline]
    fn add(&mut self, p: &BuildPrim, c2: Vec4) {
        self.bounds.grow(p.lower, p.upper);
        self.centroids.grow(c2, c2);
    }

    fn merge(&self, o: &PrimInfo) -> PrimInfo {
        PrimInfo { bounds: self.bounds.union(&o.bounds), centroids: self.centroids.union(&o.centroids) }
    }

    fn of(prims: &[BuildPrim]) -> PrimInfo {
        let mut info = PrimInfo::EMPTY;
        for p in prims {
            info.add(p, p.centroid2());
        }
        info
    }

    /// [`PrimInfo::of`] in parallel chunks (min/max reductions are exact, so the result does
    /// not depend on the thread count).
    fn of_par(prims: &[BuildPrim]) -> PrimInfo {
        use rayon::prelude::*;
        prims.par_chunks(PARALLEL_BIN_THRESHOLD / 4).map(PrimInfo::of).reduce(|| PrimInfo::EMPTY, |a, b| a.merge(&b))
    }
}

/// Relative padding of node bounds; see [`pad_outward`].
pub const BOUNDS_PADDING: f32 = 1.0 / (1 << 20) as f32;

/// Grows a node box outward by `BOUNDS_PADDING` times its largest coordinate magnitude or
/// extent. Without it, a ray travelling exactly in a box's boundary plane (a zero direction
/// component, origin on the plane) gets an empty slab interval even though the triangle test
/// hits the primitive on that plane — rays aimed straight at the shared edges of an
/// axis-aligned grid do exactly that. The padding is monotone, so children stay inside
/// their parents.
#[inline]
pub fn pad_outward(b: &Aabb) -> Aabb {
    if !b.is_valid() {
        return *b;
    }
    let scale = b.min.abs().max(b.max.abs()).max(b.extent()).max_element() * BOUNDS_PADDING;
    let scale = scale.max(f32::MIN_POSITIVE);
    Aabb { min: b.min - Vec3::splat(scale), max: b.max + Vec3::splat(scale) }
}

#[cfg(test)]
mod tests {
    use super::BuildQuality;

    #[test]
    fn quality_names_parse_back() {
        for q in BuildQuality::ALL {
            assert_eq!(q.name().parse::<BuildQuality>(), Ok(q));
            assert_eq!(q.name().to_uppercase().parse::<BuildQuality>(), Ok(q));
            assert_eq!(q.to_string(), q.name());
        }
        let err = "ultra".parse::<BuildQuality>().unwrap_err();
        assert_eq!(err.to_string(), "expected 'fast', 'medium' or 'high', got 'ultra'");
    }
}
