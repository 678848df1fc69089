//! Value parsers shared by the commands' arguments: the names of library types, read by the
//! library's own `FromStr`, so each type's names are parsed in one place.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};

use ftcbf_lab::batch::FailOn;
use ftcbf_sim::world::ControllerKindSpec;
use ftcbf_sim::worldgen::{Kind, RobotModel, Suite};

/// The value parser of an option whose values are the names of a library type: clap checks the
/// value against `values` and lists them (in `--help`, with their help, and in its errors)
/// exactly as for a `ValueEnum`; the type's own `FromStr` then reads the name, so each type's
/// names are parsed in one place, the library.
pub fn named<T>(values: impl IntoIterator<Item = PossibleValue>) -> impl TypedValueParser<Value = T>
where
    T: std::str::FromStr + Clone + Send + Sync + 'static,
    T::Err: std::error::Error + Send + Sync + 'static,
{
    PossibleValuesParser::new(values.into_iter().collect::<Vec<_>>()).try_map(|s| s.parse::<T>())
}

/// `--controller` of `run`, `batch` and `falsify`: [`ControllerKindSpec`]'s names, read by its
/// `FromStr`; `described` lists what each controller is in `--help` (as `ftcbf run --help` does).
pub fn controller_parser(described: bool) -> impl TypedValueParser<Value = ControllerKindSpec> {
    named(ControllerKindSpec::ALL.map(|kind| {
        let value = PossibleValue::new(kind.name());
        if !described {
            return value;
        }
        value.help(match kind {
            ControllerKindSpec::FtCbfClf => "Fault-tolerant CBF-CLF (the paper's controller)",
            ControllerKindSpec::Baseline => {
                "CBF-CLF over one Kalman filter that uses every sensor (the paper's comparison)"
            }
            ControllerKindSpec::Nominal => {
                "CLF only, no barriers: what happens without a safety filter"
            }
        })
    }))
}

/// `ftcbf batch --fail-on`: [`FailOn`]'s names, with what each fails on.
pub fn fail_on_parser() -> impl TypedValueParser<Value = FailOn> {
    named(FailOn::ALL.map(|level| {
        PossibleValue::new(level.name()).help(match level {
            FailOn::Refuted => {
                "Fail when a verdict is `refuted` (the interval's upper bound is below 1 − ε)"
            }
            FailOn::Unresolved => "Fail unless every verdict is `supported`",
        })
    }))
}

/// A value of `ftcbf gen --kind/--robot/--suite`: one of the library's values, or `None` for
/// every one in turn. (An alias, so that clap's derive takes it as the parsed value instead of
/// reading `Option` as "the option may be absent".)
pub type OneOrEvery<T> = Option<T>;

/// An option of `ftcbf gen` whose values are the names of a worldgen type (`all`, its
/// `name()`s) plus `every`, which reads as `None` (every value in turn). The names come from the
/// library; `help` says what each is.
fn one_or_every<T>(
    all: &'static [T],
    name: fn(T) -> &'static str,
    help: fn(T) -> &'static str,
    every: (&'static str, &'static str),
) -> impl TypedValueParser<Value = OneOrEvery<T>>
where
    T: Copy + Send + Sync + 'static,
{
    let values = all
        .iter()
        .map(|&k| PossibleValue::new(name(k)).help(help(k)))
        .chain(std::iter::once(PossibleValue::new(every.0).help(every.1)));
    PossibleValuesParser::new(values.collect::<Vec<_>>())
        .map(move |s| all.iter().copied().find(|&k| name(k) == s))
}

/// `ftcbf gen --kind`: [`Kind`]'s names, or `all`.
pub fn kind_parser() -> impl TypedValueParser<Value = OneOrEvery<Kind>> {
    one_or_every(
        &Kind::NAMED,
        Kind::name,
        |k| {
            match k {
            Kind::Room => "Four walls and furniture (tables, shelves, pillars, chairs)",
            Kind::Corridor => "A straight corridor, maybe with bins or boxes against its walls",
            Kind::Doorway => "A wall with a door, free-standing or between two rooms",
            Kind::Clutter => "A field of boxes, bins and balls",
            Kind::LTurn => "An L-shaped corridor",
            Kind::AisleCrossing => "Clutter with a cart going up and down an aisle across the route (moving)",
            Kind::CorridorWalker => "A corridor with a person walking down it and back (moving)",
            Kind::RoomPeople => "A room with two people walking across the route (moving)",
            Kind::DqnLoops => "A room with two cylinders on waypoint loops at 0.1 m/s, as the TurtleBot3 DQN stages (moving)",
            Kind::Map => "A start and a goal on an occupancy map (drawn with --map only)",
        }
        },
        ("all", "Every kind in turn"),
    )
}

/// `ftcbf gen --robot`: [`RobotModel`]'s names, or `any`.
pub fn robot_parser() -> impl TypedValueParser<Value = OneOrEvery<RobotModel>> {
    one_or_every(
        &RobotModel::ALL,
        RobotModel::name,
        |r| match r {
            RobotModel::Burger => "robots/turtlebot3_burger.urdf",
            RobotModel::Waffle => "robots/turtlebot3_waffle.urdf",
        },
        ("any", "The two in turn"),
    )
}

/// `ftcbf gen --suite`: [`Suite`]'s names, or `any`.
pub fn suite_parser() -> impl TypedValueParser<Value = OneOrEvery<Suite>> {
    one_or_every(
        &Suite::ALL,
        Suite::name,
        |s| match s {
            Suite::TwoReceivers => "Two receivers (x, y each) and an IMU heading",
            Suite::ThreeReceivers => "Three receivers and a compass",
            Suite::Odometry => "Two receivers, wheel odometry and a compass",
            Suite::Encoders => {
                "Two receivers, wheel encoders → odometry, a gyro fused with a compass"
            }
            Suite::ReceiverVelocity => {
                "Two receivers, the first also reporting velocity, and a compass"
            }
        },
        ("any", "Every suite in turn"),
    )
}
