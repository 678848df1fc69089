//! An obstacle's barrier for the controller ([`ObstacleBarrier`]): the lifted signed distance
//! to its shape with the margins of [`BarrierConfig`], a map's band, and their derivatives.

use super::*;

/// Signed distance to the points within `radius` of (c, cz), and its gradient.
pub(super) fn round_sd(
    p: Vector3<f64>,
    c: Vector2<f64>,
    cz: f64,
    radius: f64,
) -> (f64, Vector3<f64>) {
    let e = Vector3::new(p.x - c.x, p.y - c.y, p.z - cz);
    let rho = e.norm();
    if rho > 0.0 {
        (rho - radius, e / rho)
    } else {
        (-radius, Vector3::x())
    }
}

pub(super) fn coplanar(points: &[[f64; 3]]) -> bool {
    let p: Vec<Vector3<f64>> = points.iter().map(|q| Vector3::from(*q)).collect();
    let scale = p
        .iter()
        .map(|q| (q - p[0]).norm())
        .fold(0.0_f64, f64::max)
        .max(1e-12);
    // Find two independent directions, then test every point against their plane.
    let Some(a) = p.iter().map(|q| q - p[0]).find(|d| d.norm() > 1e-9 * scale) else {
        return true;
    };
    let Some(n) = p
        .iter()
        .map(|q| a.cross(&(q - p[0])))
        .find(|c| c.norm() > 1e-9 * scale * scale)
    else {
        return true;
    };
    let n = n.normalize();
    p.iter().all(|q| n.dot(&(q - p[0])).abs() <= 1e-9 * scale)
}

/// Parameters shared by all obstacle barriers of one robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BarrierConfig {
    /// Robot footprint radius r \[m\].
    pub robot_radius: f64,
    /// Height z_c at which distances are evaluated \[m\].
    pub centre_height: f64,
    /// Safety margin subtracted from the clearance \[m\].
    pub margin: f64,
    /// Gain k of the lift H = d − margin + k∇d·v \[s\].
    pub k: f64,
    /// Speed bound used in the Lipschitz bound of h̄ [m/s].
    pub v_max: f64,
    /// Step of the numerical derivatives \[m\]. Default 2e-3.
    pub fd_step: f64,
}

impl BarrierConfig {
    /// Footprint radius, centre height and v_max from a robot; `margin` \[m\] and `k` \[s\] given.
    pub fn for_robot(robot: &RobotDescription, margin: f64, k: f64) -> Self {
        Self {
            robot_radius: robot.footprint_radius,
            centre_height: robot.centre_height,
            margin,
            k,
            v_max: robot.limits.v_max,
            fd_step: 2e-3,
        }
    }
}

/// The barrier of one obstacle (implements [`ftcbf_controller::Barrier`]).
#[derive(Debug, Clone)]
pub struct ObstacleBarrier {
    pub(super) name: String,
    pub(super) obstacle: Arc<Obstacle>,
    pub(super) cfg: BarrierConfig,
    /// An occupancy map's gradient and curvature bounds over the band of its field around
    /// this barrier's zero level.
    pub(super) map_band: Option<MapBand>,
    /// One piece of an occupancy map: the barrier is the distance to it, not the field.
    pub(super) piece: Option<Outline>,
}

/// How far beyond the band where an occupancy map's lifted barrier can be zero its bounds G
/// and κ are taken \[m\]: an h̄_γ segment that moves sd by more (γ·G above it) uses the bounds
/// over the whole free space instead.
pub const MAP_BAND_SLACK: f64 = 0.1;

/// G and κ of an occupancy map over a band of its field.
#[derive(Debug, Clone, Copy)]
pub(super) struct MapBand {
    pub(super) gb: f64,
    pub(super) kappa: f64,
}

impl ObstacleBarrier {
    /// The configuration.
    pub fn config(&self) -> &BarrierConfig {
        &self.cfg
    }

    /// The bound κ on ‖∇²d‖ [1/m] that [`Barrier::h_bar`] uses, and the condition it rests on
    /// (module docs): 0 for a half-space; 1/r for a robot disc of radius r > 0 (the centre at
    /// least r from a convex obstacle); for a point robot (r = 0), 1/R for a ball, a vertical
    /// capsule and a vertical cylinder at heights within its length (the point outside the
    /// shape). `None` for a point robot and any other shape: the distance to an edge or vertex
    /// has unbounded curvature, so no h̄_γ bound exists for the lifted barrier.
    pub fn curvature_bound(&self) -> Option<f64> {
        if let Some(piece) = &self.piece {
            // distance to a convex set: ‖∇²d‖ ≤ 1/ρ, and ρ ≥ r + δ where the disc is clear
            let rho = self.cfg.robot_radius + piece.inflate;
            return (rho > 0.0).then(|| 1.0 / rho);
        }
        if let Some(b) = &self.map_band {
            return Some(b.kappa);
        }
        if self.obstacle.is_half_space() {
            return Some(0.0);
        }
        let r = self.cfg.robot_radius;
        if r > 0.0 {
            return Some(1.0 / r);
        }
        let z = self.cfg.centre_height;
        match self.obstacle.closed {
            Some(Closed::RoundSegment { radius, .. }) => Some(1.0 / radius),
            Some(Closed::VerticalCylinder {
                z_lo, z_hi, radius, ..
            }) if z >= z_lo && z <= z_hi => Some(1.0 / radius),
            _ => None,
        }
    }

    /// Clearance d(p) = sd − r of the robot disc at planar position p \[m\] (no margin, no lift).
    pub fn clearance(&self, p: Vector2<f64>) -> f64 {
        if let Some(piece) = &self.piece {
            return piece.distance_terms(p).0 - self.cfg.robot_radius;
        }
        self.obstacle
            .signed_distance(Vector3::new(p.x, p.y, self.cfg.centre_height))
            - self.cfg.robot_radius
    }

    pub(super) fn grad2(&self, p: Vector2<f64>) -> Vector2<f64> {
        if let Some(piece) = &self.piece {
            return piece.distance_terms(p).1;
        }
        let (_, g) = self
            .obstacle
            .sd_and_grad(Vector3::new(p.x, p.y, self.cfg.centre_height));
        g.xy()
    }

    pub(super) fn hess2_numeric(&self, p: Vector2<f64>) -> Matrix2<f64> {
        let h = self.cfg.fd_step;
        let mut m = Matrix2::zeros();
        for j in 0..2 {
            let mut e = Vector2::zeros();
            e[j] = h;
            let col = (self.grad2(p + e) - self.grad2(p - e)) / (2.0 * h);
            m.set_column(j, &col);
        }
        0.5 * (m + m.transpose())
    }

    /// (d, ∇d, ∇²d, D(∇²d·v)) in the plane.
    pub(super) fn planar_terms(
        &self,
        p: Vector2<f64>,
        v: Vector2<f64>,
    ) -> (f64, Vector2<f64>, Matrix2<f64>, Matrix2<f64>) {
        let z = self.cfg.centre_height;
        let r = self.cfg.robot_radius;
        if let Some(piece) = &self.piece {
            let (d, g, m) = piece.distance_terms(p);
            let dmv = if m == Matrix2::zeros() {
                m
            } else {
                // round at a vertex: the same derivative as a ball's, at ρ = d + δ
                let rho = d + piece.inflate;
                let s = g.dot(&v);
                let w = m * v;
                -(s * m + g * w.transpose() + w * g.transpose()) / rho
            };
            return (d - r, g, m, dmv);
        }
        let p3 = Vector3::new(p.x, p.y, z);
        let round = match self.obstacle.closed {
            Some(Closed::HalfSpace { n, p0 }) => {
                return (
                    n.dot(&(p3 - p0)) - r,
                    n.xy(),
                    Matrix2::zeros(),
                    Matrix2::zeros(),
                )
            }
            Some(Closed::RoundSegment {
                c,
                z_lo,
                z_hi,
                radius,
            }) => Some((c, z - z.clamp(z_lo, z_hi), radius)),
            Some(Closed::VerticalCylinder {
                c,
                z_lo,
                z_hi,
                radius,
            }) if z >= z_lo && z <= z_hi => Some((c, 0.0, radius)),
            _ => None,
        };
        if let Some((c, dz, radius)) = round {
            let e = p - c;
            let rho = (e.norm_squared() + dz * dz).sqrt();
            if rho > 1e-12 {
                let g = e / rho;
                let m = (Matrix2::identity() - g * g.transpose()) / rho;
                let s = g.dot(&v);
                let w = m * v;
                let dmv = -(s * m + g * w.transpose() + w * g.transpose()) / rho;
                return (rho - radius - r, g, m, dmv);
            }
        }
        // Numerical curvature terms around parry's projection normal.
        let (sd, g3) = self.obstacle.sd_and_grad(p3);
        let m = self.hess2_numeric(p);
        let h = self.cfg.fd_step;
        let mut dmv = Matrix2::zeros();
        for j in 0..2 {
            let mut e = Vector2::zeros();
            e[j] = h;
            let col = (self.hess2_numeric(p + e) * v - self.hess2_numeric(p - e) * v) / (2.0 * h);
            dmv.set_column(j, &col);
        }
        (sd - r, g3.xy(), m, 0.5 * (dmv + dmv.transpose()))
    }
}

impl Barrier for ObstacleBarrier {
    fn name(&self) -> &str {
        &self.name
    }

    fn eval(&self, x: &State) -> BarrierEval {
        let p = Vector2::new(x[0], x[1]);
        let v = Vector2::new(x[2], x[3]);
        let k = self.cfg.k;
        let (d, g, m, dmv) = self.planar_terms(p, v);
        let value = d - self.cfg.margin + k * g.dot(&v);
        let gp = g + k * (m * v);
        let gradient = State::new(gp.x, gp.y, k * g.x, k * g.y);
        let pp = m + k * dmv;
        let pv = k * m;
        let mut hessian = StateMatrix::zeros();
        hessian.fixed_view_mut::<2, 2>(0, 0).copy_from(&pp);
        hessian.fixed_view_mut::<2, 2>(0, 2).copy_from(&pv);
        hessian
            .fixed_view_mut::<2, 2>(2, 0)
            .copy_from(&pv.transpose());
        BarrierEval {
            value,
            gradient,
            hessian,
        }
    }

    /// γ·L with L = √((1 + k·v_max·κ)² + k²), κ = [`ObstacleBarrier::curvature_bound`]; see
    /// the module docs for the conditions under which it bounds h̄_γ. +∞ when the lift is on
    /// (k > 0) and no curvature bound is known (the runner refuses such worlds first).
    fn h_bar(&self, gamma: f64) -> f64 {
        let k = self.cfg.k;
        let l = if let (Some(g), Some(band)) = (&self.obstacle.grid, &self.map_band) {
            // The map's ‖∇d‖ ≤ G (not 1): L = √((G + k·v_max·κ)² + (k·G)²), with G and κ of
            // the band around the zero level when the segment stays in it.
            let (gb, kappa) = if gamma.max(0.0) * g.gradient_bound() <= MAP_BAND_SLACK {
                (band.gb, band.kappa)
            } else {
                (g.gradient_bound(), g.curvature_bound())
            };
            ((gb + k * self.cfg.v_max * kappa).powi(2) + (k * gb).powi(2)).sqrt()
        } else if k == 0.0 {
            1.0
        } else {
            match self.curvature_bound() {
                Some(kappa) => ((1.0 + k * self.cfg.v_max * kappa).powi(2) + k * k).sqrt(),
                None => f64::INFINITY,
            }
        };
        gamma.max(0.0) * l
    }
}
