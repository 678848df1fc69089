//! `environment.map` (issue #47 part B): map_server's YAML with PGM (P5, P2) and PNG images,
//! cell positions, the distance field against brute force, the physics' boxes against the
//! barrier's distance, and bad maps refused with the key named.

use std::path::{Path, PathBuf};

use ftcbf_sim::environment::map::{squared_distance_transform, Cell, MapYaml, MAX_MAP_CELLS};
use ftcbf_sim::environment::{MapField, OccupancyGrid};
use ftcbf_sim::world::{UnknownCells, World};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/worlds_map")
        .join(name)
}

#[test]
fn a_p5_map_with_unknown_cells_and_a_turned_origin() {
    let g = OccupancyGrid::load(&fixture("room.yaml")).unwrap();
    assert_eq!((g.width, g.height, g.resolution), (20, 16, 0.1));
    assert_eq!(g.origin, [1.0, -2.0, 0.5]);
    // Rows count from the bottom: the file's last row is row 0.
    assert_eq!(g.cell(6, 5), Cell::Occupied);
    assert_eq!(g.cell(10, 4), Cell::Occupied);
    assert_eq!(g.cell(11, 4), Cell::Occupied);
    assert_eq!(g.cell(14, 10), Cell::Unknown); // 205: p = 0.196 is not below free_thresh 0.196
    assert_eq!(g.cell(16, 12), Cell::Unknown);
    assert_eq!(g.cell(3, 3), Cell::Free);
    assert_eq!(g.cell(0, 7), Cell::Occupied);
    // By hand: origin (1, −2) + R(0.5)·(0.65, 0.55), cos 0.5 = 0.877583, sin 0.5 = 0.479426:
    // x = 1 + 0.570429 − 0.263684 = 1.306745, y = −2 + 0.311627 + 0.482670 = −1.205703.
    let c = g.cell_centre(6, 5);
    assert!(
        (c[0] - 1.306745).abs() < 0.01 && (c[1] + 1.205703).abs() < 0.01,
        "{c:?}"
    );
    assert!(
        (c[0] - 1.306745).abs() < 1e-5 && (c[1] + 1.205703).abs() < 1e-5,
        "{c:?}"
    );
    // The far corner (20, 16) cells: (1 + 0.877583·2 − 0.479426·1.6, −2 + 0.479426·2 + 0.877583·1.6)
    // = (1.988085, 0.362984).
    let f = g.to_world(20.0, 16.0);
    assert!(
        (f[0] - 1.988085).abs() < 1e-5 && (f[1] - 0.362984).abs() < 1e-5,
        "{f:?}"
    );
    let field = MapField::new(&g, UnknownCells::Obstacle);
    // The single occupied cell's centre is inside; a free cell's centre outside.
    assert!(field.signed_distance(c).0 < 0.0);
    let free = g.cell_centre(4, 8);
    let (d, _) = field.signed_distance(free);
    assert!(d > 0.0, "{d}");
}

#[test]
fn a_p2_map_with_negate() {
    let g = OccupancyGrid::load(&fixture("negate.yaml")).unwrap();
    assert_eq!((g.width, g.height), (6, 4));
    // File rows top-first: row 3 of the file is map row 0, all 15 (white, occupied when negated).
    for i in 0..6 {
        assert_eq!(g.cell(i, 0), Cell::Occupied);
    }
    assert_eq!(g.cell(1, 2), Cell::Occupied);
    assert_eq!(g.cell(3, 1), Cell::Occupied);
    assert_eq!(g.cell(4, 2), Cell::Unknown); // 8/15 = 0.53: between the thresholds
    assert_eq!(g.cell(0, 3), Cell::Free);
    let c = g.cell_centre(3, 1);
    assert!(
        (c[0] - 0.175).abs() < 1e-9 && (c[1] - 0.075).abs() < 1e-9,
        "{c:?}"
    );
}

#[test]
fn a_png_map_in_scale_mode() {
    let g = OccupancyGrid::load(&fixture("scale.yaml")).unwrap();
    assert_eq!((g.width, g.height), (8, 6));
    for i in 0..8 {
        assert_eq!(g.cell(i, 5), Cell::Occupied, "top row, cell {i}");
    }
    assert_eq!(g.cell(2, 2), Cell::Occupied);
    assert_eq!(g.cell(5, 4), Cell::Unknown, "transparent");
    assert_eq!(g.cell(6, 1), Cell::Unknown, "grey between the thresholds");
    assert_eq!(g.cell(0, 0), Cell::Free);
    let free = g.cells.iter().filter(|c| **c == Cell::Free).count();
    assert_eq!(free, 48 - 8 - 1 - 2);
    // Cell (2, 2): (−1 + 2.5·0.25, 0.5 + 2.5·0.25) = (−0.375, 1.125).
    let c = g.cell_centre(2, 2);
    assert!(
        (c[0] + 0.375).abs() < 1e-9 && (c[1] - 1.125).abs() < 1e-9,
        "{c:?}"
    );
}

#[test]
fn the_mode_key_reads_raw_values_as_percent() {
    let y = MapYaml {
        image: PathBuf::new(),
        resolution: 0.05,
        origin: [0.0; 3],
        negate: false,
        occupied_thresh: 0.65,
        free_thresh: 0.196,
        mode: ftcbf_sim::environment::map::Mode::Raw,
    };
    assert_eq!(y.classify(100.0 / 255.0, true), Cell::Occupied);
    assert_eq!(y.classify(0.0, true), Cell::Free);
    assert_eq!(y.classify(50.0 / 255.0, true), Cell::Unknown);
    assert_eq!(y.classify(1.0, true), Cell::Unknown); // 255 = −1 in nav2's raw maps
}

fn load_err(name: &str) -> String {
    OccupancyGrid::load(&fixture(name)).unwrap_err().to_string()
}

#[test]
fn bad_maps_are_refused_naming_the_key() {
    let e = load_err("missing_image.yaml");
    assert!(e.contains("`image`") && e.contains("nowhere.pgm"), "{e}");
    let e = load_err("bad_resolution.yaml");
    assert!(e.contains("`resolution`") && e.contains("1e-9"), "{e}");
    // 10⁸ cells in the header: refused from the header, nothing allocated.
    let e = load_err("huge.yaml");
    assert!(
        e.contains("100000 × 1000") && e.contains(&MAX_MAP_CELLS.to_string()),
        "{e}"
    );
    let e = load_err("no_such.yaml");
    assert!(
        e.contains("no_such.yaml") && e.contains("cannot be read"),
        "{e}"
    );
}

#[test]
fn bad_yaml_keys_are_named() {
    let dir = std::env::temp_dir().join(format!("ftcbf_map_keys_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(fixture("room.pgm"), dir.join("room.pgm")).unwrap();
    let cases = [
        ("origin: [0, 0]", "`origin`"),
        ("origin: [0, 0, 0]\nresolutoin: 0.05", "resolutoin"),
        ("origin: [0, 0, 0]\nmode: fuzzy", "`mode`"),
        ("origin: [0, 0, 0]\nnegate: 2", "`negate`"),
        ("origin: [1e9, 0, 0]", "`origin (x)`"),
        ("origin: [0, 0, 0\n", "line"),
    ];
    for (extra, want) in cases {
        let p = dir.join("m.yaml");
        let body = format!(
            "image: room.pgm\nresolution: 0.05\noccupied_thresh: 0.65\nfree_thresh: 0.196\n{extra}\n"
        );
        std::fs::write(&p, body).unwrap();
        let e = OccupancyGrid::load(&p).unwrap_err().to_string();
        assert!(e.contains(want) && e.contains("m.yaml"), "{extra:?}: {e}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The exact transform against the nearest site by brute force, on random grids.
#[test]
fn the_distance_transform_is_exact() {
    let mut rng = ChaCha8Rng::seed_from_u64(47);
    for _ in 0..20 {
        let (nx, ny) = (rng.random_range(1..40), rng.random_range(1..40));
        let p = rng.random_range(0.01..0.5);
        let site: Vec<bool> = (0..nx * ny).map(|_| rng.random_bool(p)).collect();
        let d = squared_distance_transform(&site, nx, ny);
        for j in 0..ny {
            for i in 0..nx {
                let mut best = f64::INFINITY;
                for (k, _) in site.iter().enumerate().filter(|(_, s)| **s) {
                    let (a, b) = ((k % nx) as f64, (k / nx) as f64);
                    best = best.min((a - i as f64).powi(2) + (b - j as f64).powi(2));
                }
                let got = d[j * nx + i];
                if best.is_finite() {
                    assert_eq!(got, best, "cell ({i}, {j}) of {nx} × {ny}");
                } else {
                    assert!(got >= 1e29);
                }
            }
        }
    }
}

/// Signed distance from `p` (map frame, cells) to the union of the blocked unit squares, by
/// brute force; beyond the map is free.
fn brute_sd(blocked: &[bool], w: usize, h: usize, p: [f64; 2]) -> f64 {
    let to_square = |i: usize, j: usize| {
        let dx = (i as f64 - p[0]).max(p[0] - (i + 1) as f64).max(0.0);
        let dy = (j as f64 - p[1]).max(p[1] - (j + 1) as f64).max(0.0);
        (dx * dx + dy * dy).sqrt()
    };
    let mut to_blocked = f64::INFINITY;
    // Distance to the free region: free squares, and beyond the map's edge.
    let mut to_free = p[0]
        .min(p[1])
        .min(w as f64 - p[0])
        .min(h as f64 - p[1])
        .max(0.0);
    for j in 0..h {
        for i in 0..w {
            if blocked[j * w + i] {
                to_blocked = to_blocked.min(to_square(i, j));
            } else {
                to_free = to_free.min(to_square(i, j));
            }
        }
    }
    if to_blocked > 0.0 {
        to_blocked
    } else {
        -to_free
    }
}

/// The field is a lower bound of the signed distance to the blocked squares, within its
/// stated error (3·res/√2), on random grids with random origins and yaws.
#[test]
fn the_distance_field_is_within_its_bound_of_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(4747);
    let mut worst = 0.0f64;
    for _ in 0..30 {
        let (w, h) = (rng.random_range(2..25), rng.random_range(2..25));
        let res = rng.random_range(0.02..0.3);
        let origin = [
            rng.random_range(-5.0..5.0),
            rng.random_range(-5.0..5.0),
            rng.random_range(-3.2..3.2),
        ];
        let one = rng.random_range(0..w * h);
        let cells: Vec<Cell> = (0..w * h)
            .map(|k| {
                if k == one || rng.random_bool(0.15) {
                    Cell::Occupied
                } else {
                    Cell::Free
                }
            })
            .collect();
        let blocked: Vec<bool> = cells.iter().map(|c| *c == Cell::Occupied).collect();
        let g = OccupancyGrid {
            width: w,
            height: h,
            resolution: res,
            origin,
            cells,
        };
        let field = MapField::new(&g, UnknownCells::Free);
        for _ in 0..200 {
            let q = [
                rng.random_range(-2.0..w as f64 + 2.0),
                rng.random_range(-2.0..h as f64 + 2.0),
            ];
            let truth = brute_sd(&blocked, w, h, q) * res;
            let (got, grad) = field.signed_distance(g.to_world(q[0], q[1]));
            assert!(got <= truth + 1e-9, "{got} > {truth} at {q:?}");
            // Beyond the map (and its one-cell rim) the field falls with slope 1 from the edge:
            // still a lower bound, but where beyond is free it drifts from the truth.
            let rim = |c: f64, n: usize| (-0.5..=n as f64 + 0.5).contains(&c);
            if !(rim(q[0], w) && rim(q[1], h)) {
                continue;
            }
            assert!(
                truth - got <= field.error_bound() + 1e-9,
                "{truth} − {got} > {} at {q:?}",
                field.error_bound()
            );
            assert!(grad.norm() <= field.gradient_bound() + 1.0 + 1e-9);
            worst = worst.max((truth - got) / res);
        }
    }
    // The bound is not vacuous: the field comes within 3/√2 cells and uses some of it.
    assert!(worst > 0.5 && worst <= 3.0 / 2f64.sqrt(), "{worst}");
}

/// The room fixture's world (`room_world_base.toml`) with `extra` tables and
/// `[environment] map = "room.yaml"`, loaded from the fixture folder.
fn room_map_world(extra: &str) -> World {
    let text = format!(
        "{}\n{extra}\n[environment]\nmap = \"room.yaml\"\n",
        include_str!("../../tests/worlds_map/room_world_base.toml")
    );
    World::from_str(&text, &fixture("").join("room.toml"), &[]).unwrap()
}

#[test]
fn a_world_with_a_map_loads_and_its_boxes_agree_with_its_field() {
    let dir = fixture("");
    let world = room_map_world("");
    let map = world.obstacles.iter().find(|o| o.name == "map").unwrap();
    let field = map.map_field().unwrap();
    let grid = OccupancyGrid::load(&dir.join("room.yaml")).unwrap();
    // Far fewer boxes than blocked cells (merged runs), walls closing the map included.
    let boxes = grid.rectangles(UnknownCells::Obstacle).len();
    let blocked = grid
        .cells
        .iter()
        .filter(|c| c.blocked(UnknownCells::Obstacle))
        .count();
    assert!(boxes * 3 < blocked, "{boxes} boxes for {blocked} cells");
    // The physics' boxes and the field: parry's distance at z = 0.1 (inside the boxes'
    // height) is the true distance; the field is below it by at most its bound.
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..300 {
        let q = [rng.random_range(0.5..19.5), rng.random_range(0.5..15.5)];
        let p = grid.to_world(q[0], q[1]);
        let proj = map.shape().project_point(
            map.shape_pose(),
            parry3d::math::Vector::new(p[0] as f32, p[1] as f32, 0.1),
            false,
        );
        let diff =
            ((proj.point.x as f64 - p[0]).powi(2) + (proj.point.y as f64 - p[1]).powi(2)).sqrt();
        let parry_sd = if proj.is_inside { -diff } else { diff };
        let (sd, _) = field.signed_distance(p);
        assert!(sd <= parry_sd + 1e-4, "{sd} > {parry_sd} at {q:?}");
        assert!(
            parry_sd - sd <= field.error_bound() + 1e-4,
            "{parry_sd} vs {sd}"
        );
    }
}

#[test]
fn environment_keys_are_checked() {
    let dir = fixture("");
    let base = include_str!("../../tests/worlds_map/room_world_base.toml");
    let load = |extra: &str| {
        World::from_str(&format!("{base}\n{extra}"), &dir.join("room.toml"), &[])
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    let e = load("[environment]\nmap = \"missing_image.yaml\"\n");
    assert!(
        e.contains("environment.map") && e.contains("`image`"),
        "{e}"
    );
    let e = load("[environment]\nunknown = \"free\"\n");
    assert!(e.contains("environment.unknown"), "{e}");
    let e = load("[environment]\nmap = \"room.yaml\"\nunknown = \"maybe\"\n");
    assert!(e.contains("unknown"), "{e}");
    let e = load(
        "[[obstacles]]\nname = \"m\"\nshape = { kind = \"occupancy_map\", file = \"room.yaml\" }\n",
    );
    // Not a kind a world file may write, and not offered as one.
    let first = e.lines().next().unwrap();
    assert!(first.contains("unknown variant `occupancy_map`"), "{e}");
    assert!(!first.contains("`tri_mesh`, `occupancy_map`"), "{e}");
}

/// The map's barrier: h = sd_map − r − margin at rest, its gradient the field's, a finite
/// h̄_γ from the band's bounds (never above the whole map's), and O(1) lookups.
#[test]
fn the_map_barrier_reads_the_field() {
    use ftcbf_sim::ftcbf_controller::{Barrier, State};
    use ftcbf_sim::obstacles::BarrierConfig;
    let world = room_map_world("");
    let map = world.obstacles.iter().find(|o| o.name == "map").unwrap();
    let field = map.map_field().unwrap();
    let cfg = BarrierConfig {
        robot_radius: 0.1,
        centre_height: 0.1,
        margin: 0.02,
        k: 0.5,
        v_max: 0.22,
        fd_step: 2e-3,
    };
    let b = map.barrier(&cfg);
    let p = [0.9, -1.086];
    let (sd, g) = field.signed_distance(p);
    let at_rest = b.eval(&State::new(p[0], p[1], 0.0, 0.0));
    assert!((at_rest.value - (sd - 0.1 - 0.02)).abs() < 1e-12);
    assert!((at_rest.gradient[2] - 0.5 * g.x).abs() < 1e-12);
    let v = State::new(p[0], p[1], 0.1, -0.05);
    let moving = b.eval(&v);
    assert!((moving.value - (sd - 0.12 + 0.5 * (g.x * 0.1 - g.y * 0.05))).abs() < 1e-12);
    let kappa = b.curvature_bound().unwrap();
    assert!(kappa.is_finite() && kappa <= field.curvature_bound() + 1e-12);
    let small = b.h_bar(0.05);
    let l_all = ((field.gradient_bound() + 0.5 * 0.22 * field.curvature_bound()).powi(2)
        + (0.5 * field.gradient_bound()).powi(2))
    .sqrt();
    assert!(small.is_finite() && small > 0.0 && small <= 0.05 * l_all + 1e-12);
    // A γ whose segment leaves the band uses the whole map's bounds.
    assert!((b.h_bar(1.0) - l_all).abs() < 1e-9);
}

/// The nearest blocked cell, as `check` reports it, against a search of every cell.
#[test]
fn the_nearest_blocked_cell_is_found() {
    let g = OccupancyGrid::load(&fixture("room.yaml")).unwrap();
    let field = MapField::new(&g, UnknownCells::Obstacle);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..50 {
        let q = [rng.random_range(-3.0..23.0), rng.random_range(-3.0..19.0)];
        let p = g.to_world(q[0], q[1]);
        let n = field.nearest_blocked(p).unwrap();
        let mut best = f64::INFINITY;
        for j in -1..=16i64 {
            for i in -1..=20i64 {
                let inside = (0..20).contains(&i) && (0..16).contains(&j);
                if inside
                    && !g
                        .cell(i as usize, j as usize)
                        .blocked(UnknownCells::Obstacle)
                {
                    continue;
                }
                let c = g.to_world(i as f64 + 0.5, j as f64 + 0.5);
                best = best.min(((c[0] - p[0]).powi(2) + (c[1] - p[1]).powi(2)).sqrt());
            }
        }
        assert!((n.distance - best).abs() < 1e-9, "{n:?} vs {best} at {q:?}");
        let c = g.to_world(n.cell.0 as f64 + 0.5, n.cell.1 as f64 + 0.5);
        assert!((c[0] - n.centre[0]).abs() < 1e-9 && (c[1] - n.centre[1]).abs() < 1e-9);
    }
    // (6, 5) is the lone occupied cell: a point on it finds it.
    let n = field.nearest_blocked(g.cell_centre(6, 5)).unwrap();
    assert_eq!(n.cell, (6, 5));
}

/// The controller keeps a map with one barrier per piece of its outline (issue #47: the field's
/// single barrier had κ ≈ 39 1/m and the robot stalled): each piece's clearance is never above
/// the robot disc's true clearance from the physics' boxes (parry) and at most two cells below
/// it, and each gets the convex obstacles' curvature bound 1/(r + δ), not the field's.
#[test]
fn the_map_barriers_are_its_pieces_and_keep_the_robot_off_the_boxes() {
    use ftcbf_sim::obstacles::BarrierConfig;
    let dir = fixture("");
    let world = room_map_world("");
    let map = world.obstacles.iter().find(|o| o.name == "map").unwrap();
    let grid = OccupancyGrid::load(&dir.join("room.yaml")).unwrap();
    let cfg = BarrierConfig {
        robot_radius: 0.1,
        centre_height: 0.1,
        margin: 0.02,
        k: 0.5,
        v_max: 0.22,
        fd_step: 2e-3,
    };
    let pieces = map.barriers(&cfg);
    assert_eq!(pieces.len(), map.outlines().len());
    assert!(pieces.len() >= 4, "{} pieces", pieces.len());
    for (b, o) in pieces.iter().zip(map.outlines()) {
        let kappa = b.curvature_bound().unwrap();
        assert!((kappa - 1.0 / (0.1 + o.inflate)).abs() < 1e-12, "{kappa}");
        assert!(o.inflate <= grid.resolution + 1e-12);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut checked = 0;
    for _ in 0..400 {
        let q = [rng.random_range(0.5..19.5), rng.random_range(0.5..15.5)];
        let p = grid.to_world(q[0], q[1]);
        let proj = map.shape().project_point(
            map.shape_pose(),
            parry3d::math::Vector::new(p[0] as f32, p[1] as f32, 0.1),
            false,
        );
        if proj.is_inside {
            continue;
        }
        let truth = ((proj.point.x as f64 - p[0]).powi(2) + (proj.point.y as f64 - p[1]).powi(2))
            .sqrt()
            - 0.1;
        let least = pieces
            .iter()
            .map(|b| b.clearance(nalgebra::Vector2::new(p[0], p[1])))
            .fold(f64::INFINITY, f64::min);
        assert!(least <= truth + 1e-4, "{least} > {truth} at {q:?}");
        assert!(
            truth - least <= 2.0 * grid.resolution + 1e-4,
            "{truth} vs {least} at {q:?}"
        );
        checked += 1;
    }
    assert!(checked > 100, "{checked} free points");
}

/// The office fixture (a P5 map as map_saver writes it, unknown cells outside the walls, its
/// origin at (−2, −1) turned 0.2 rad): the desk and the pillar become one convex polygon each,
/// placed within 1 cm of where the map's origin and yaw put them (computed by hand).
#[test]
fn the_office_map_places_its_desk_and_pillar_within_a_centimetre() {
    use ftcbf_sim::environment::outline::{outlines, DEFAULT_TOLERANCE_CELLS};
    let grid = OccupancyGrid::load(&fixture("office.yaml")).unwrap();
    let pieces = outlines(&grid, UnknownCells::Obstacle, DEFAULT_TOLERANCE_CELLS);
    let (s, c) = 0.2f64.sin_cos();
    let world = |x: f64, y: f64| [-2.0 + c * x - s * y, -1.0 + s * x + c * y];
    let centroid = |pts: &[nalgebra::Vector2<f64>]| {
        pts.iter().fold(nalgebra::Vector2::zeros(), |a, p| a + p) / pts.len() as f64
    };
    let nearest = |target: [f64; 2]| {
        pieces
            .iter()
            .filter(|p| p.is_polygon())
            .min_by(|a, b| {
                let t = nalgebra::Vector2::from(target);
                (centroid(&a.points) - t)
                    .norm()
                    .total_cmp(&(centroid(&b.points) - t).norm())
            })
            .unwrap()
    };
    // The desk: cells whose centres lie in |x − 5.2| ≤ 0.4, |y − 1.2| ≤ 0.25 (map frame), so
    // its squares span x ∈ [4.8, 5.6], y ∈ [0.95, 1.45].
    let desk = nearest(world(5.2, 1.2));
    assert_eq!(desk.points.len(), 4, "{:?}", desk.points);
    for corner in [(4.8, 0.95), (5.6, 0.95), (5.6, 1.45), (4.8, 1.45)] {
        let want = nalgebra::Vector2::from(world(corner.0, corner.1));
        let got = desk
            .points
            .iter()
            .map(|p| (p - want).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(got < 0.01, "desk corner {corner:?}: {got} m off");
    }
    // The pillar: a disc of radius 0.2 m at (1.8, 3.2); its cells' hull is centred there.
    let pillar = nearest(world(1.8, 3.2));
    let centre = nalgebra::Vector2::from(world(1.8, 3.2));
    assert!((centroid(&pillar.points) - centre).norm() < 0.01);
    for p in &pillar.points {
        let r = (p - centre).norm();
        assert!(
            (0.19..=0.25).contains(&r),
            "pillar vertex {r} m from the centre"
        );
    }
}

/// A start or goal inside a blocked region of the map is an error naming the key, the map and
/// the cell (issue #47): the outline pieces' distance is unsigned, so a barrier alone would
/// not say so, and a run would start inside the walls.
#[test]
fn a_start_or_goal_in_a_blocked_cell_is_refused_naming_the_map_and_the_cell() {
    let dir = fixture("");
    let g = OccupancyGrid::load(&dir.join("room.yaml")).unwrap();
    let base = include_str!("../../tests/worlds_map/room_world_base.toml");
    let with = |start: [f64; 2], goal: [f64; 2]| {
        let text = base
            .replace(
                "start = { x = 0.90, y = -1.086, theta = 0.5 }",
                &format!(
                    "start = {{ x = {}, y = {}, theta = 0.5 }}",
                    start[0], start[1]
                ),
            )
            .replace(
                "center = [2.184, -0.726]",
                &format!("center = [{}, {}]", goal[0], goal[1]),
            );
        World::from_str(
            &format!("{text}\n[environment]\nmap = \"room.yaml\"\n"),
            &dir.join("room.toml"),
            &[],
        )
        .map(|_| ())
    };
    let (start, goal) = ([0.90, -1.086], [2.184, -0.726]);
    with(start, goal).expect("the base world's start and goal are free");
    // (6, 5): the lone occupied cell, 0.3 m from the free start cell.
    let e = with(g.cell_centre(6, 5), goal).unwrap_err().to_string();
    assert!(
        e.contains("robot.start")
            && e.contains("blocked cell (6, 5)")
            && e.contains("room.yaml")
            && e.contains("must be in a free cell"),
        "{e}"
    );
    // (16, 12) is unknown, blocked by default.
    let e = with(start, g.cell_centre(16, 12)).unwrap_err().to_string();
    assert!(
        e.contains("goal.center") && e.contains("blocked cell (16, 12)"),
        "{e}"
    );
    // Beyond the map's edge (unknown = obstacle): the rim's cell, −1 on that side.
    let e = with(g.to_world(-0.5, 3.5), goal).unwrap_err().to_string();
    assert!(e.contains("blocked cell (-1, 3)"), "{e}");
    // A point just inside a free cell next to the occupied one is not refused.
    let c = g.to_world(7.05, 5.5);
    assert!(g.cell(7, 5) == Cell::Free);
    let field = MapField::new(&g, UnknownCells::Obstacle);
    assert_eq!(field.blocked_cell_at(c), None);
    assert_eq!(field.blocked_cell_at(g.to_world(6.95, 5.5)), Some((6, 5)));
}

/// `check` on a map world with an input box: its rest-demand pass samples each barrier's
/// boundary and once read obstacle `k` for barrier `k`, past the end of the obstacle list when
/// the map gives one barrier per outline piece (an index panic, found by `ftcbf gen --map`).
#[test]
fn check_runs_on_a_map_world_with_an_input_limit() {
    let world = room_map_world("[control]\ninput_limit = 1.0\n");
    let map = world.obstacles.iter().find(|o| o.name == "map").unwrap();
    assert!(map.barrier_count() > 1, "{}", map.barrier_count());
    let report = ftcbf_sim::analysis::check::check_world(&world).unwrap();
    assert!(report.barrier_names.iter().any(|n| n.contains("map#1")));
}
