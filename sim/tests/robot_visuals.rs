//! URDF visual meshes: loaded for drawing where the files exist, warnings otherwise.

use std::path::{Path, PathBuf};

use ftcbf_sim::robot::{DriveLimits, LoadOptions, RobotDescription};

fn ros_burger() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/urdf/turtlebot3_burger_ros.urdf")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ftcbf-visuals-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// An ASCII STL tetrahedron with corners at the origin and `e` along each axis [file units].
fn write_tetrahedron(path: &Path, e: f32) {
    let p = [[0.0, 0.0, 0.0], [e, 0.0, 0.0], [0.0, e, 0.0], [0.0, 0.0, e]];
    let mut s = String::from("solid tet\n");
    for t in [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
        s.push_str("facet normal 0 0 0\nouter loop\n");
        for i in t {
            let [x, y, z] = p[i];
            s.push_str(&format!("vertex {x} {y} {z}\n"));
        }
        s.push_str("endloop\nendfacet\n");
    }
    s.push_str("endsolid tet\n");
    std::fs::write(path, s).unwrap();
}

fn opts(pkgs: &Path) -> LoadOptions {
    LoadOptions {
        package_paths: vec![pkgs.to_path_buf()],
        limits: Some(DriveLimits {
            v_max: 0.22,
            omega_max: 2.84,
            wheel_speed_max: 0.22 / 0.033,
        }),
        ..LoadOptions::default()
    }
}

#[test]
fn visual_meshes_that_exist_are_loaded_scaled_and_placed() {
    let pkgs = scratch("found");
    let meshes = pkgs.join("turtlebot3_description/meshes");
    std::fs::create_dir_all(meshes.join("bases")).unwrap();
    write_tetrahedron(&meshes.join("bases/burger_base.stl"), 100.0); // mm, scale 0.001
    let r = RobotDescription::from_file(ros_burger(), &opts(&pkgs)).unwrap();
    let base = &r.bodies[0];
    assert_eq!(base.visuals.len(), 1, "{:?}", r.warnings);
    let v = &base.visuals[0];
    assert_eq!(v.link, "base_link");
    assert_eq!(v.indices.len(), 4);
    let max = v
        .vertices
        .iter()
        .flatten()
        .copied()
        .fold(f64::MIN, f64::max);
    assert!((max - 0.1).abs() < 1e-9, "scaled to metres: {max}");
    // <origin xyz="-0.032 0 0"> of the visual, on top of base_link's 0.010 m above the footprint.
    let t = v.pose_in_body.translation.vector;
    assert!((t.x + 0.032).abs() < 1e-9 && t.y.abs() < 1e-9, "{t:?}");
    // The wheels have no mesh on disk: no visuals, three warnings (left, right tire, caster).
    assert!(r.bodies[1..].iter().all(|b| b.visuals.is_empty()));
    assert_eq!(r.warnings.len(), 3, "{:?}", r.warnings);
    let _ = std::fs::remove_dir_all(&pkgs);
}

#[test]
fn an_unreadable_visual_mesh_is_a_warning_naming_link_and_file() {
    let pkgs = scratch("broken");
    let meshes = pkgs.join("turtlebot3_description/meshes/bases");
    std::fs::create_dir_all(&meshes).unwrap();
    std::fs::write(meshes.join("burger_base.stl"), b"not an stl").unwrap();
    let r = RobotDescription::from_file(ros_burger(), &opts(&pkgs)).unwrap();
    assert!(r.bodies.iter().all(|b| b.visuals.is_empty()));
    let w = r
        .warnings
        .iter()
        .find(|w| w.contains("burger_base.stl"))
        .expect("a warning for the broken file");
    assert!(w.contains("base_link") && w.contains("unreadable"), "{w}");
    let _ = std::fs::remove_dir_all(&pkgs);
}
