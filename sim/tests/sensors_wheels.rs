//! Wheel encoders and the odometry derived from them (#12): count-difference quantisation, the
//! diff-drive kinematics of `from_wheels`, and an attack on an encoder reaching the odometry.

use std::f64::consts::TAU;

use ftcbf_sim::robot::WheelGeometry;
use ftcbf_sim::sensors::{ChannelSpec, Quantity, SensorSuite};
use ftcbf_sim::state::TruthState;

const DT: f64 = 0.02;
/// TurtleBot3 burger: wheel radius and separation [m].
const BURGER: WheelGeometry = WheelGeometry {
    radius: 0.033,
    separation: 0.16,
};

/// Wheels turning at constant speeds (left, right) [rad/s] from angle 0 at t = 0.
fn truth(k: i64, left: f64, right: f64) -> TruthState {
    let t = k as f64 * DT;
    TruthState {
        t,
        wheel_left: left,
        wheel_right: right,
        wheel_angle_left: left * t,
        wheel_angle_right: right * t,
        ..Default::default()
    }
}

fn encoders(ticks: Option<u32>) -> Vec<ChannelSpec> {
    let mut l = ChannelSpec::new("enc_l", Quantity::WheelLeft, 0.0);
    let mut r = ChannelSpec::new("enc_r", Quantity::WheelRight, 0.0);
    l.ticks_per_rev = ticks;
    r.ticks_per_rev = ticks;
    let mut v = ChannelSpec::new("odom_v", Quantity::Speed, 0.0);
    v.from_wheels = Some(["enc_l".into(), "enc_r".into()]);
    let mut w = ChannelSpec::new("odom_w", Quantity::YawRate, 0.0);
    w.from_wheels = Some(["enc_l".into(), "enc_r".into()]);
    vec![l, r, v, w]
}

/// A 4096-count encoder at 50 Hz reads whole counts per period: every reading is a multiple of
/// q = 2π/(4096·0.02) = 0.0767 rad/s, within one step of the truth, and the readings average to
/// the truth (the count differences telescope: the mean over n periods is off by < 1 count / n).
#[test]
fn quantised_encoder_reads_whole_counts_and_averages_to_the_truth() {
    let mut suite = SensorSuite::new(&encoders(Some(4096)), DT, 1).unwrap();
    suite.set_wheel_geometry(Some(BURGER));
    let q = TAU / (4096.0 * DT);
    let (left, right) = (5.1234, 6.789);
    let n = 500;
    let mut sum = 0.0;
    for k in 0..n {
        let s = suite.sample(&truth(k, left, right));
        let counts = s[0].value / q;
        assert!(
            (counts - counts.round()).abs() < 1e-9,
            "tick {k}: {counts} counts"
        );
        assert!(
            (s[0].value - left).abs() <= q + 1e-12,
            "tick {k}: {}",
            s[0].value
        );
        assert_eq!(s[0].clean, left);
        if k > 0 {
            sum += s[0].value;
        }
    }
    let mean = sum / (n - 1) as f64;
    assert!(
        (mean - left).abs() <= q / (n - 1) as f64 + 1e-12,
        "mean {mean} vs {left}"
    );
}

/// The odometry of two noise-free encoders is the diff-drive kinematics of the truth:
/// v = r(ω_l + ω_r)/2 and ω = r(ω_r − ω_l)/L. Without a wheel geometry it is NaN (not a guess).
#[test]
fn odometry_from_wheels_is_the_diff_drive_kinematics() {
    let (left, right) = (4.0, 6.0);
    let mut suite = SensorSuite::new(&encoders(None), DT, 1).unwrap();
    suite.set_wheel_geometry(Some(BURGER));
    let s = suite.sample(&truth(3, left, right));
    assert!((s[2].value - 0.033 * 5.0).abs() < 1e-15, "{}", s[2].value);
    assert!(
        (s[3].value - 0.033 * 2.0 / 0.16).abs() < 1e-15,
        "{}",
        s[3].value
    );
    assert!(s[2].fresh && s[3].fresh);
    let mut bare = SensorSuite::new(&encoders(None), DT, 1).unwrap();
    assert!(bare.sample(&truth(3, left, right))[2].value.is_nan());
}

/// An attack on one encoder reaches the odometry made from it: +3 rad/s on the left wheel moves
/// v by r·3/2 = 0.0495 m/s and ω by −r·3/L; an attack on the odometry itself stays as it is.
#[test]
fn an_attack_on_an_encoder_reaches_the_odometry() {
    let mut suite = SensorSuite::new(&encoders(None), DT, 1).unwrap();
    suite.set_wheel_geometry(Some(BURGER));
    let (v0, w0) = {
        let s = suite.sample(&truth(0, 4.0, 6.0));
        (s[2].value, s[3].value)
    };
    let s = suite.sample(&truth(1, 4.0, 6.0));
    s[0].value += 3.0; // the attack on enc_l
    s[3].value += 0.1; // and one on the yaw-rate odometry itself
    let s = suite.propagate_attacks();
    assert!(
        (s[2].value - (v0 + 0.033 * 1.5)).abs() < 1e-12,
        "{}",
        s[2].value
    );
    assert!(
        (s[3].value - (w0 + 0.1 - 0.033 * 3.0 / 0.16)).abs() < 1e-12,
        "{}",
        s[3].value
    );
    // A non-finite encoder reading makes the odometry non-finite (the controller rejects it).
    let s = suite.sample(&truth(2, 4.0, 6.0));
    s[1].value = f64::NAN;
    assert!(suite.propagate_attacks()[2].value.is_nan());
}
