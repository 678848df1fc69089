//! Active barriers (issue #52): the obstacles' [`BarrierIndex`] for the controller, a parry
//! BVH over their bounding boxes, with the far-field bounds of their lifted barriers.
//!
//! The controller builds a row only for the barriers within its reach radius of an estimate
//! (the rule and its proof: [`ftcbf_controller::reach`]). What this module certifies, for the
//! lifted barrier `H = d − margin + k∇d·v` of [`crate::obstacles`] (d = sd − r) of every
//! covered obstacle, at a planar position p whose distance to the obstacle's region (the xy
//! extent of its bounding box, widened by [`REGION_PAD`]) is D, at speed s = ‖v‖, with
//! ρ = D − 2·fd_step (the finite differences look up to two steps away):
//!
//! - d ≥ D − r: the distance from (p, z_c) to the solid is at least the planar distance to the
//!   xy extent of its box, so `H ≥ D − r − margin − k·s` (‖∇d‖ = 1);
//! - ‖∇²d‖: outside a convex set the unit normal ∇sd is (1/ρ)-Lipschitz at distance ≥ ρ (the
//!   projection's I − Dπ has norm ≤ 1), so each column of the central-difference Hessian (and
//!   of the closed form (I − ggᵀ)/ρ) has norm ≤ 1/ρ: `‖∇²d‖_F ≤ √2/ρ`;
//! - ‖D(∇²d·v)‖_F ≤ 2s/(h·ρ) for the numerical form (two columns, each a difference of two
//!   vectors of norm ≤ √2·s/ρ over 2h; symmetrising does not raise the Frobenius norm) and
//!   3s/ρ² for the closed form of round shapes;
//! - so ‖∇H‖ ≤ 1 + k + k·s·√2/ρ and ‖∇²H‖_F ≤ √2/ρ + k·‖D(∇²d·v)‖_F + 2k·√2/ρ (block by block).
//!
//! Covered: the convex shapes with a bounded extent whose projection parry computes exactly
//! (cuboid; ball, cylinder, capsule in closed form). Not covered, so evaluated at every step:
//! cones and convex hulls (parry's support-map projection is iterative: its normal is not
//! Lipschitz to the last bit, and the central differences amplify that), half-spaces
//! (unbounded), triangle meshes (not convex: the normal jumps across the medial axis),
//! occupancy maps (one obstacle spanning the map), and closed-form safe sets.

use ftcbf_controller::reach::{BarrierIndex, FarBounds, ReachTerms};
use ftcbf_controller::{ControllerConfig, State, StateMatrix};
use parry3d::bounding_volume::Aabb;
use parry3d::math::Vector;
use parry3d::partitioning::{Bvh, BvhBuildStrategy};

use crate::obstacles::{BarrierConfig, Obstacle, ShapeSpec};

/// How much each obstacle's region is widened beyond parry's (f32) bounding box \[m\]: far
/// above the f32 rounding of the box and of the point projections behind d.
pub const REGION_PAD: f64 = 1e-3;

/// Below this ρ \[m\] nothing is certified (the bounds grow without limit).
const MIN_RHO: f64 = 0.01;

/// The parry BVH over the covered obstacles' regions (leaf data: the barrier's position in the
/// controller's list) and the bounds of the module docs.
#[derive(Debug)]
pub struct ObstacleIndex {
    bvh: Bvh,
    covered: Vec<bool>,
    /// Planar regions [x_min, y_min, x_max, y_max] by barrier position (None: not covered).
    regions: Vec<Option<[f64; 4]>>,
    cfg: BarrierConfig,
    /// Whether some covered obstacle's derivatives are numerical (not a round closed form).
    numeric: bool,
}

/// Whether the obstacle's barrier is covered (module docs), and whether its derivatives are the
/// round closed forms.
fn coverage(o: &Obstacle, cfg: &BarrierConfig) -> Option<bool> {
    match &o.spec.shape {
        ShapeSpec::Ball { .. } => Some(false),
        ShapeSpec::Capsule { .. } | ShapeSpec::Cylinder { .. } => {
            let z = cfg.centre_height;
            let h = match o.spec.shape {
                ShapeSpec::Capsule { .. } => f64::INFINITY,
                ShapeSpec::Cylinder { half_height, .. } => half_height,
                _ => 0.0,
            };
            let upright = o.spec.rpy[0] == 0.0 && o.spec.rpy[1] == 0.0;
            Some(!(upright && (z - o.spec.position[2]).abs() <= h))
        }
        ShapeSpec::Cuboid { .. } => Some(true),
        // parry projects onto cones and hulls by support-map iterations: the normal it returns
        // is not 1/ρ-Lipschitz to the last bit, and the central differences amplify that (the
        // bound failed in tests/active_barriers.rs); they are evaluated at every step.
        ShapeSpec::Cone { .. }
        | ShapeSpec::ConvexHull { .. }
        | ShapeSpec::HalfSpace { .. }
        | ShapeSpec::TriMesh { .. }
        | ShapeSpec::OccupancyMap { .. } => None,
    }
}

impl ObstacleIndex {
    /// The index over `obstacles`, whose barriers sit at positions `offset..` of the
    /// controller's list of `total` barriers (built with `cfg`), in the order
    /// [`Obstacle::barriers`] gives them.
    pub fn new(obstacles: &[Obstacle], offset: usize, total: usize, cfg: &BarrierConfig) -> Self {
        let mut covered = vec![false; total];
        let mut regions = vec![None; total];
        let mut numeric = false;
        let mut leaves = Vec::new();
        // An obstacle's barriers follow one another: one each, or one per piece of an
        // occupancy map's outline (`Obstacle::barriers`), which the index does not cover.
        let mut next = offset;
        for o in obstacles {
            let at = next;
            next += o.barrier_count();
            if !o.outlines().is_empty() {
                continue;
            }
            let Some(num) = coverage(o, cfg) else {
                continue;
            };
            let b = o.shape().compute_aabb(o.shape_pose());
            let r = [
                b.mins.x as f64 - REGION_PAD,
                b.mins.y as f64 - REGION_PAD,
                b.maxs.x as f64 + REGION_PAD,
                b.maxs.y as f64 + REGION_PAD,
            ];
            if !r.iter().all(|v| v.is_finite()) || at >= total {
                continue;
            }
            numeric |= num;
            covered[at] = true;
            regions[at] = Some(r);
            let leaf = Aabb::new(
                Vector::new(r[0] as f32, r[1] as f32, -1.0),
                Vector::new(r[2] as f32, r[3] as f32, 1.0),
            );
            leaves.push((at, leaf));
        }
        Self {
            bvh: Bvh::from_iter(BvhBuildStrategy::Binned, leaves),
            covered,
            regions,
            cfg: *cfg,
            numeric,
        }
    }

    /// Number of covered barriers.
    pub fn covered_count(&self) -> usize {
        self.covered.iter().filter(|&&c| c).count()
    }

    /// The planar distance from `p` to barrier `b`'s region (None: not covered).
    pub fn distance(&self, b: usize, p: [f64; 2]) -> Option<f64> {
        let r = self.regions.get(b).copied().flatten()?;
        let dx = (r[0] - p[0]).max(p[0] - r[2]).max(0.0);
        let dy = (r[1] - p[1]).max(p[1] - r[3]).max(0.0);
        Some(dx.hypot(dy))
    }
}

impl BarrierIndex for ObstacleIndex {
    fn covers(&self, b: usize) -> bool {
        self.covered.get(b).copied().unwrap_or(false)
    }

    fn far_bounds(&self, dist: f64, speed: f64) -> FarBounds {
        let c = &self.cfg;
        let h = c.fd_step;
        let rho = dist - 2.0 * h;
        if !(rho >= MIN_RHO && speed.is_finite() && speed >= 0.0) {
            return FarBounds {
                h_lower: f64::NEG_INFINITY,
                gradient: f64::INFINITY,
                hessian: f64::INFINITY,
            };
        }
        let k = c.k;
        let m = std::f64::consts::SQRT_2 / rho;
        let dmv = if self.numeric {
            2.0 * speed / (h * rho)
        } else {
            3.0 * speed / (rho * rho)
        };
        FarBounds {
            h_lower: dist - c.robot_radius - c.margin - k * speed,
            gradient: 1.0 + k + k * speed * m,
            hessian: m + k * dmv + 2.0 * k * m,
        }
    }

    fn near(&self, p: [f64; 2], radius: f64, out: &mut Vec<usize>) {
        let r = radius + REGION_PAD;
        let q = Aabb::new(
            Vector::new((p[0] - r) as f32, (p[1] - r) as f32, -2.0),
            Vector::new((p[0] + r) as f32, (p[1] + r) as f32, 2.0),
        );
        for leaf in self.bvh.intersect_aabb(&q) {
            out.push(leaf as usize);
        }
    }
}

/// Which of `cfg`'s barriers are out of reach ([`ftcbf_controller::reach`]) of the estimate
/// `x` of a unit with gain terms `m` (K c̄), `n` (Kν̄ν̄ᵀKᵀ), error bound γ and class-K gain κ:
/// every input of the box satisfies their rows, so a caller that looks for the inputs the rows
/// allow (liveness) may leave them out. Empty (nothing out of reach) without an index, without
/// an input box, or when the radius is not finite.
pub fn out_of_reach(
    cfg: &ControllerConfig,
    x: &State,
    (m, n): (&StateMatrix, &StateMatrix),
    gamma: f64,
    kappa: f64,
) -> Vec<bool> {
    let (Some(index), Some(limit)) = (cfg.barrier_index.as_deref(), cfg.input_limit) else {
        return Vec::new();
    };
    let h_bar = cfg
        .barriers
        .iter()
        .enumerate()
        .filter(|(b, _)| index.covers(*b))
        .map(|(_, b)| b.h_bar(gamma))
        .fold(0.0_f64, f64::max);
    let terms = ReachTerms::new(
        &cfg.model.f,
        &cfg.model.g,
        limit.norm(),
        x,
        m,
        n,
        gamma,
        kappa,
        h_bar,
        cfg.delta,
    );
    let radius = terms.radius(index);
    if !(radius.is_finite() && x[0].is_finite() && x[1].is_finite()) {
        return Vec::new();
    }
    let mut far: Vec<bool> = (0..cfg.barriers.len()).map(|b| index.covers(b)).collect();
    let mut near = Vec::new();
    index.near([x[0], x[1]], radius, &mut near);
    for b in near {
        if let Some(f) = far.get_mut(b) {
            *f = false;
        }
    }
    far
}
