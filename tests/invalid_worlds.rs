//! Every file under tests/invalid_worlds/ is a world a person could plausibly write wrong. Each
//! must be rejected with an error that names the file and says what is wrong: its first line
//! `# expect-error: TEXT` gives a substring the message must contain.

use std::path::PathBuf;

use ftcbf_sim::world::World;

#[test]
fn every_invalid_world_is_rejected_with_a_helpful_message() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/invalid_worlds");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("tests/invalid_worlds exists")
        .map(|e| e.expect("readable entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(
        files.len() >= 25,
        "the catalogue has {} worlds, expected at least 25",
        files.len()
    );
    let mut problems = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).expect("readable");
        let expect = text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix("# expect-error: "))
            .unwrap_or_else(|| panic!("{}: first line must be `# expect-error: TEXT`", f.display()))
            .to_string();
        match World::load(f, &[]) {
            Ok(_) => problems.push(format!(
                "{}: accepted, expected an error containing {expect:?}",
                f.display()
            )),
            Err(e) => {
                let msg = e.to_string();
                let name = f.file_name().and_then(|n| n.to_str()).unwrap_or_default();
                if !msg.contains(&expect) {
                    problems.push(format!(
                        "{name}: message {msg:?} does not contain {expect:?}"
                    ));
                }
                if !msg.contains(name) {
                    problems.push(format!("{name}: message {msg:?} does not name the file"));
                }
            }
        }
    }
    assert!(
        problems.is_empty(),
        "{} problem(s):\n{}",
        problems.len(),
        problems.join("\n")
    );
}

/// Issue #29: an error inside a nested table names the dotted key path (array indices
/// included), the file, the line and column of the key, and what was found and expected — for
/// every kind of nested table, the `kind`-tagged ones (an obstacle's `shape`, `[[safe_sets]]`,
/// `[[attacks]]`) included, whose errors used to point at the table's header without a key.
#[test]
fn errors_in_nested_tables_name_the_key_path_line_and_column() {
    struct Case {
        world: &'static str,
        from: &'static str,
        to: &'static str,
        key: &'static str,
        /// The text the line and column must point at: inside `to`, else the last before it.
        at: &'static str,
        says: &'static str,
    }
    let cylinder = r#"shape = { kind = "cylinder", radius = 0.15, half_height = 0.2 }"#;
    let cases = [
        Case {
            world: "doorway_clutter.toml",
            from: cylinder,
            to: r#"shape = { kind = "cylinder", radius = 0.15, half_height = "0.2" }"#,
            key: "obstacles[2].shape.half_height",
            at: "half_height",
            says: r#"invalid type: string "0.2", expected a number"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "half_extents = [0.2, 0.2, 0.1]",
            to: r#"half_extents = [0.2, "x", 0.1]"#,
            key: "obstacles[3].shape.half_extents[1]",
            at: r#""x""#,
            says: r#"invalid type: string "x", expected a number"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: cylinder,
            to: r#"shape = { kind = "cylinder", radius = 0.15 }"#,
            key: "obstacles[2].shape.half_height",
            at: "shape",
            says: "missing field `half_height`",
        },
        Case {
            world: "doorway_clutter.toml",
            from: cylinder,
            to: r#"shape = { kind = "cylinder", radius = 0.15, height = 0.2 }"#,
            key: "obstacles[2].shape.height",
            at: "height = 0.2",
            says: "unknown field `height`, expected `radius` or `half_height`",
        },
        Case {
            world: "doorway_clutter.toml",
            from: cylinder,
            to: r#"shape = { kind = "cilinder", radius = 0.15, half_height = 0.2 }"#,
            key: "obstacles[2].shape.kind",
            at: "kind",
            says: "unknown variant `cilinder`, expected one of `cuboid`, `ball`, `cylinder`",
        },
        Case {
            world: "doorway_clutter.toml",
            from: cylinder,
            to: r#"shape = { radius = 0.15, half_height = 0.2 }"#,
            key: "obstacles[2].shape.kind",
            at: "shape",
            says: r#"missing; expected one of "cuboid", "ball", "cylinder""#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "velocity = [0.0, 0.04]",
            to: r#"velocity = [0.0, "fast"]"#,
            key: "attacks[0].velocity[1]",
            at: r#""fast""#,
            says: r#"invalid type: string "fast", expected a number"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "start = 4.0\nvelocity = [0.0, 0.04]",
            to: "start = 4.0",
            key: "attacks[0].velocity",
            at: "[[attacks]]",
            says: "missing field `velocity`",
        },
        Case {
            world: "doorway_clutter.toml",
            from: "start = 4.0",
            to: r#"start = "4 s""#,
            key: "attacks[0].start",
            at: "start",
            says: r#"invalid type: string "4 s", expected a number"#,
        },
        Case {
            world: "paper_turtlebot.toml",
            from: "a = [0.0, 1.0, 0.0, 0.2]",
            to: "a = [0.0, 1.0, 0.2]",
            key: "safe_sets[0].a",
            at: "a =",
            says: "invalid length 3, expected an array of length 4",
        },
        Case {
            world: "paper_turtlebot.toml",
            from: "b = -0.05",
            to: "b = \"low\"",
            key: "safe_sets[0].b",
            at: "b =",
            says: r#"invalid type: string "low", expected a number"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "name = \"odom_vx\"\nmeasures = \"vx\"\nnoise_std = 0.02",
            to: "name = \"odom_vx\"\nmeasures = \"vx\"\nnoise_std = \"0.02\"",
            key: "sensors[4].noise_std",
            at: "noise_std",
            says: r#"invalid type: string "0.02", expected a number"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "measures = \"vx\"",
            to: "measures = \"vz\"",
            key: "sensors[4].measures",
            at: "measures",
            says: "unknown variant `vz`, expected one of",
        },
        Case {
            world: "doorway_clutter.toml",
            from: "name = \"gnss2\"\nchannels = [\"gnss2_x\", \"gnss2_y\"]",
            to: "name = \"gnss2\"\nchannels = \"gnss2_x\"",
            key: "fault_patterns[1].channels",
            at: "channels",
            says: r#"invalid type: string "gnss2_x", expected an array"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "start = { x = 0.0, y = 0.0, theta = 0.0 }",
            to: "start = { x = 0.0, y = \"0\", theta = 0.0 }",
            key: "robot.start.y",
            at: "y = \"0\"",
            says: r#"invalid type: string "0", expected a number"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "start = { x = 0.0, y = 0.0, theta = 0.0 }",
            to: "start = { x = 0.0, y = 0.0, theta = 0.0 }\nlimits = { v_max = 0.2, omega_max = 2.0 }",
            key: "robot.limits.wheel_speed_max",
            at: "limits",
            says: "missing field `wheel_speed_max`",
        },
        Case {
            world: "doorway_clutter.toml",
            from: "dt = 0.005",
            to: "dt = \"fast\"",
            key: "physics.dt",
            at: "dt",
            says: r#"invalid type: string "fast", expected a number"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "\n[goal]\n",
            to: "\n[control.drive]\ndv_max = \"1\"\n\n[goal]\n",
            key: "control.drive.dv_max",
            at: "dv_max",
            says: r#"invalid type: string "1", expected a number"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "\n[goal]\n",
            to: "\n[control.drive]\nlow_speed = \"smooth\"\n\n[goal]\n",
            key: "control.drive.low_speed",
            at: "low_speed",
            says: "unknown variant `smooth`, expected `floor` or `regularised`",
        },
        Case {
            world: "doorway_clutter.toml",
            from: "\n[goal]\n",
            to: "\n[control.nominal]\ncruise_sped = 0.2\n\n[goal]\n",
            key: "control.nominal.cruise_sped",
            at: "cruise_sped",
            says: "unknown field `cruise_sped`, expected one of `cruise_speed`",
        },
        Case {
            world: "doorway_clutter.toml",
            from: "\n[goal]\n",
            to: "\n[control.clf]\nrho = \"fast\"\n\n[goal]\n",
            key: "control.clf.rho",
            at: "rho",
            says: r#"invalid type: string "fast", expected"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "epsilon = 0.05",
            to: "gamma = \"automatic\"\nepsilon = 0.05",
            key: "control.gamma",
            at: "gamma",
            says: r#"expected a number or "auto", found "automatic""#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "center = [3.0, 0.0]",
            to: "center = [3.0, 0.0]\nwaypoints = [[1.0, 0.0], [2.0]]",
            key: "goal.waypoints[1]",
            at: "[2.0]",
            says: "invalid length 1, expected an array of length 2",
        },
        Case {
            world: "paper_linear.toml",
            from: "x0 = [1.0, 0.0, 0.0, 0.0]",
            to: "x0 = [1.0, 0.0, \"a\", 0.0]",
            key: "linear.x0[2]",
            at: "\"a\"",
            says: r#"invalid type: string "a", expected a number"#,
        },
        Case {
            world: "doorway_clutter.toml",
            from: "min_h = { at_least = 0.1190, tolerance = 0.0238 }",
            to: "min_h = { at_least = 0.1190 }",
            key: "expect.min_h",
            at: "min_h",
            says: "missing `tolerance`",
        },
    ];
    let mut problems = Vec::new();
    for c in &cases {
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("worlds")
            .join(c.world);
        let original = std::fs::read_to_string(&path).expect("catalogue world");
        assert_eq!(
            original.matches(c.from).count(),
            1,
            "{}: `{}` must occur once",
            c.world,
            c.from
        );
        let text = original.replacen(c.from, c.to, 1);
        // Where the message must point: `at` inside the replacement, as 1-based line and column.
        let start = original.find(c.from).expect("found above");
        // (or, for a key the file leaves out, the last `at` before it: its table's header)
        let offset = match c.to.find(c.at) {
            Some(i) => start + i,
            None => text[..start].rfind(c.at).expect("`at` precedes `to`"),
        };
        let line = text[..offset].matches('\n').count() + 1;
        let column = text[..offset]
            .rsplit('\n')
            .next()
            .map_or(0, |l| l.chars().count())
            + 1;
        let want = format!("{}:{line}:{column}: `{}`: {}", c.world, c.key, c.says);
        match World::from_str(&text, &path, &[]) {
            Ok(_) => problems.push(format!("{}: accepted", c.key)),
            Err(e) => {
                let msg = e.to_string();
                if !msg.contains(&want) {
                    problems.push(format!("{}:\n  got  {msg}\n  want {want}", c.key));
                }
            }
        }
    }
    assert!(
        problems.is_empty(),
        "{} of {} case(s):\n{}",
        problems.len(),
        cases.len(),
        problems.join("\n")
    );
}

/// A `--set` that no longer fits the schema names the key path inside a tagged table too.
#[test]
fn an_override_that_breaks_a_tagged_table_names_the_key_inside_it() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("worlds/doorway_clutter.toml");
    let ov = ftcbf_sim::world::Override::parse("obstacles[0].shape.radius=0.1").expect("override");
    let e = World::load(&path, &[ov])
        .expect_err("a cuboid has no radius")
        .to_string();
    assert!(
        e.contains("`obstacles[0].shape.radius`: unknown field `radius`, expected `half_extents`"),
        "{e}"
    );
}
