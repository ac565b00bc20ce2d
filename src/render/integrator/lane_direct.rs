//! The direct lighting of points shaded in lanes, added up in lanes once their shadow rays are
//! traced: per lane, [`Integrator::direct_total`]'s sums in its order, so the same bits.

use super::{Integrator, PathState};
use crate::math::Vec3;
use crate::render::queue::{DirectQueue, LanePoints, LaneSample};
use crate::simd::isa::{IsaOp, dispatch};
use crate::simd::{IsaLanes, Lanes, Vec3x};

impl Integrator<'_> {
    /// Adds the direct lighting of the lane points of `d` (their shadow rays traced) to their
    /// paths: per lane, [`Integrator::direct_total`] of its samples times its weight, the same
    /// sums bit for bit.
    pub fn add_direct_lanes(&self, d: &DirectQueue, paths: &mut [PathState]) {
        let Some(lights) = &self.lane_lights else { return };
        if d.lanes.is_empty() {
            return;
        }
        dispatch(self.scene.isa(), DirectLanes { d, paths, groups: &lights.samples, divisors: &lights.divisors });
    }
}

/// Direct lighting added in lanes, run on one ISA.
struct DirectLanes<'a> {
    d: &'a DirectQueue,
    paths: &'a mut [PathState],
    /// Each sample row's light (its group) and that group's samples per point.
    groups: &'a [(u32, bool)],
    divisors: &'a [f32],
}

impl IsaOp for DirectLanes<'_> {
    type Output = ();
    #[inline(always)]
    fn run<I: IsaLanes>(self) {
        for (i, points) in self.d.lanes.iter().enumerate() {
            let add = direct_lanes::<I::F8>(points, self.d.lane_samples_of(i), self.groups, self.divisors);
            for j in crate::simd::bits(points.mask) {
                self.paths[points.path[j] as usize].l += add.lane(j);
            }
        }
    }
}

/// `weight · direct_total(samples)` of each lane of `points`: each group's visible values
/// summed in draw order and divided by its divisor, where the lane queued any sample of it.
#[inline(always)]
fn direct_lanes<V: Lanes>(
    points: &LanePoints,
    rows: &[LaneSample],
    groups: &[(u32, bool)],
    divisors: &[f32],
) -> Vec3x<V> {
    let zero = Vec3x::<V>::splat(Vec3::ZERO);
    let mut total = zero;
    let mut i = 0;
    while i < rows.len() {
        let group = groups[i].0;
        let (mut sum, mut queued) = (zero, 0);
        let divisor = V::splat(divisors[i]);
        while i < rows.len() && groups[i].0 == group {
            let r = &rows[i];
            sum = Vec3x::select(V::from_bitmask(r.visible), sum + Vec3x::load_rows(&r.value), sum);
            queued |= r.kept;
            i += 1;
        }
        total = Vec3x::select(V::from_bitmask(queued), total + sum / divisor, total);
    }
    let w = Vec3x::<V>::load_rows(&points.weight);
    Vec3x { x: w.x * total.x, y: w.y * total.y, z: w.z * total.z }
}
