//! The default blueprint: what the viewer shows, with no clicking, when a recording opens.
//!
//! Left: the 3D scene (robot, estimates with trails, safe sets, goal) above the event log.
//! Right, top to bottom: h on the truth and on each estimate per barrier (tabs, safe sets
//! first); clean vs received per channel (tabs, attacked channels first, attack windows drawn);
//! the Step-3 residues, detector statistics and V/V₀ (tabs); v, ω, u and the attack windows (tabs).

use rerun::blueprint::{
    Blueprint, BlueprintPanel, ContainerLike, Horizontal, SelectionPanel, Spatial3DView, Tabs,
    TextLogView, TimePanel, TimeSeriesView, Vertical,
};

use super::draw::{colour_name, seg};
use crate::observe::Scene;

fn plot(name: String, origin: String) -> ContainerLike {
    TimeSeriesView::new(name).with_origin(origin).into()
}

/// Channels in the order their tabs appear: attacked ones first.
fn channel_order(scene: &Scene) -> Vec<(&String, bool)> {
    let attacked = |c: &String| scene.attack_channels.iter().any(|a| a.contains(c));
    let mut v: Vec<(&String, bool)> = scene.channels.iter().map(|c| (c, attacked(c))).collect();
    v.sort_by_key(|(_, a)| !*a);
    v
}

/// The viewer layout for `scene`.
pub(crate) fn blueprint(scene: &Scene) -> Blueprint {
    let names: Vec<String> = scene
        .filters
        .iter()
        .enumerate()
        .map(|(i, f)| format!("{f} ({})", colour_name(i)))
        .collect();
    let view3d = Spatial3DView::new(format!(
        "{}: robot and trail (black) = truth; estimates {}; safe sets red, goal green",
        scene.world,
        names.join(", ")
    ))
    .with_origin("/world");
    let log = TextLogView::new("events: policy, safety, attacks").with_origin("/events");
    let barriers = Tabs::new(scene.barriers.iter().map(|b| {
        plot(
            format!("h_{b}: truth (black) and per estimate; below 0 is unsafe"),
            format!("/barriers/{}", seg(b)),
        )
    }));
    let sensors = Tabs::new(channel_order(scene).into_iter().map(|(c, attacked)| {
        let what = if attacked { " (attacked)" } else { "" };
        plot(
            format!("{c}{what}: clean (grey) vs received (red), rejected (dots)"),
            format!("/sensors/{}", seg(c)),
        )
    }));
    let stats = Tabs::new([
        plot(
            "Step-3 residue per estimator, log10".into(),
            "/residues".into(),
        ),
        plot(
            "detector statistic z per channel (|z| ≤ 3 normal)".into(),
            "/detector".into(),
        ),
        plot("CLF V/V₀ per estimator".into(), "/clf".into()),
    ]);
    let control = Tabs::new([
        TimeSeriesView::new("command to the drive: v [m/s], ω [rad/s]")
            .with_contents(["/control/v", "/control/omega"])
            .into(),
        TimeSeriesView::new("controller input u [m/s²]")
            .with_contents(["/control/u_x", "/control/u_y"])
            .into(),
        plot("attack windows (1 = active)".into(), "/attacks".into()),
    ]);
    let plots = Vertical::new([
        barriers.into(),
        sensors.into(),
        stats.into(),
        control.into(),
    ]);
    let left = Vertical::new([view3d.into(), log.into()]).with_row_shares([3.0, 1.0]);
    Blueprint::new(Horizontal::new([left.into(), plots.into()]).with_column_shares([1.2, 1.0]))
        .with_auto_views(false)
        .with_blueprint_panel(BlueprintPanel::new().with_state(collapsed()))
        .with_selection_panel(SelectionPanel::new().with_state(collapsed()))
        .with_time_panel(
            TimePanel::new()
                .with_timeline("sim_time")
                .with_state(collapsed()),
        )
}

fn collapsed() -> rerun::blueprint::components::PanelState {
    rerun::blueprint::components::PanelState::Collapsed
}
