//! h̄_γ bounds rest on numbers the world gives, never on invented ones: a linear world's
//! lifted barriers need `[linear] v_max`, and a point robot's lifted barrier needs a shape whose
//! distance has bounded curvature (issue 16).

use std::path::Path;

use ftcbf_sim::model::setup::ControlSetup;
use ftcbf_sim::runner::RunError;
use ftcbf_sim::world::{ControllerKindSpec, World, WorldError};

fn paper_linear_with(extra_linear: &str, extra: &str) -> World {
    load_paper_linear_with(extra_linear, extra).unwrap()
}

fn load_paper_linear_with(extra_linear: &str, extra: &str) -> Result<World, WorldError> {
    let base = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/paper_linear.toml"),
    )
    .unwrap();
    let text = base
        .replace(
            "process_noise = 1e-3          # Q = 1e-3 I, the paper's",
            &format!("process_noise = 1e-3\n{extra_linear}"),
        )
        .replace("[expect]", &format!("{extra}\n[expect]"));
    World::from_str(&text, Path::new("h_bar_inputs.toml"), &[])
}

/// The key and message a world whose h̄_γ would need an invented number is refused with: by
/// the world's validation (issue 29: `check` and `run` refuse it alike), which runs the same
/// test as the controller setup.
fn setup_error(w: Result<World, WorldError>) -> (String, String) {
    match w {
        Err(WorldError::Invalid { key, message, .. }) => (key, message),
        Err(e) => panic!("unexpected error {e}"),
        Ok(w) => match ControlSetup::new(&w, ControllerKindSpec::FtCbfClf) {
            Err(RunError::Setup { key, message, .. }) => (key, message),
            Err(e) => panic!("unexpected error {e}"),
            Ok(_) => panic!("setup accepted a world whose h̄_γ needs an invented number"),
        },
    }
}

const ELLIPSE: &str = r#"
[[safe_sets]]
kind = "ellipse_inside"
name = "arena"
center = [0.0, 0.0]
semi_axes = [3.0, 2.0]
angle = 0.0
lift = 0.5
"#;

const BALL: &str = r#"
[[obstacles]]
name = "rock"
position = [0.0, 2.0, 0.0]
shape = { kind = "ball", radius = 0.25 }
"#;

const BOX: &str = r#"
[[obstacles]]
name = "crate"
position = [0.0, 2.0, 0.0]
shape = { kind = "cuboid", half_extents = [0.2, 0.2, 0.2] }
"#;

#[test]
fn a_lifted_barrier_of_a_linear_world_needs_its_speed_bound() {
    for extra in [ELLIPSE, BALL] {
        let (key, message) = setup_error(load_paper_linear_with("", extra));
        assert_eq!(key, "linear.v_max", "{message}");
        assert!(message.contains("v_max = "), "{message}");
    }
    // an ellipse without a lift does not depend on the speed
    let w = paper_linear_with("", &ELLIPSE.replace("lift = 0.5", "lift = 0.0"));
    assert!(ControlSetup::new(&w, ControllerKindSpec::FtCbfClf).is_ok());
    // zero or negative bounds are rejected by the world validation, naming the key
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/paper_linear.toml"),
    )
    .unwrap()
    .replace("[control]", "v_max = 0.0\n[control]");
    let e = World::from_str(&text, Path::new("x.toml"), &[]).unwrap_err();
    assert!(e.to_string().contains("linear.v_max"), "{e}");
}

#[test]
fn the_given_speed_bound_and_the_shapes_curvature_set_h_bar() {
    let w = paper_linear_with("v_max = 0.8", &format!("{ELLIPSE}{BALL}"));
    let s = ControlSetup::new(&w, ControllerKindSpec::FtCbfClf).unwrap();
    let barriers = &s.config.barriers;
    assert_eq!(barriers.len(), 3); // floor, arena, rock
    let gamma = 0.04;
    // ball, point robot: κ = 1/R = 4, k = obstacle_lift (0.5 by default), v_max = 0.8
    let (k, kappa, v) = (0.5, 4.0, 0.8);
    let want = gamma * ((1.0f64 + k * v * kappa).powi(2) + k * k).sqrt();
    assert!(
        (barriers[2].h_bar(gamma) - want).abs() < 1e-12,
        "{} vs {want}",
        barriers[2].h_bar(gamma)
    );
    // the ellipse's bound uses the same v_max: ‖∇_p H‖ ≤ 2λ̄(a + k·v_max), ‖∇_v H‖ ≤ 2kλ̄a
    let (lmax, a) = (1.0 / 4.0, 3.0);
    let gp = 2.0 * lmax * (a + 0.5 * v);
    let gv = 2.0 * 0.5 * lmax * a;
    let want = gamma * (gp * gp + gv * gv).sqrt();
    assert!((barriers[1].h_bar(gamma) - want).abs() < 1e-12);
    // before: κ = 1/max(r, 1e-3) = 1000 for the point robot, h̄ ≈ 200 γ here
    assert!(barriers[2].h_bar(gamma) < 3.0 * gamma); // ≈ 2.65 γ
}

#[test]
fn a_point_robots_lifted_barrier_on_a_shape_with_edges_is_refused() {
    let (key, message) = setup_error(load_paper_linear_with("v_max = 0.8", BOX));
    assert_eq!(key, "obstacles[0].shape", "{message}");
    assert!(
        message.contains("crate") && message.contains("cuboid") && message.contains("curvature"),
        "{message}"
    );
    // without the lift the barrier is the plain distance (L = 1): accepted, h̄ = γ
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/paper_linear.toml"),
    )
    .unwrap()
    .replace("[control]", "[control]\nobstacle_lift = 0.0")
    .replace("[expect]", &format!("{BOX}\n[expect]"));
    let unlifted = World::from_str(&text, Path::new("x.toml"), &[]).unwrap();
    let s = ControlSetup::new(&unlifted, ControllerKindSpec::FtCbfClf).unwrap();
    assert!((s.config.barriers[1].h_bar(0.04) - 0.04).abs() < 1e-15);
    // a half-space never needs a curvature bound
    let wall = BOX.replace(
        "shape = { kind = \"cuboid\", half_extents = [0.2, 0.2, 0.2] }",
        "shape = { kind = \"half_space\", normal = [0.0, -1.0, 0.0] }",
    );
    assert!(ControlSetup::new(&paper_linear_with("", &wall), ControllerKindSpec::FtCbfClf).is_ok());
}
