//! The world file as text, written the way a user writes one: one `[[obstacles]]` table per
//! obstacle with an inline `shape`, one `[[sensors]]` table per channel, short numbers.

use std::fmt::Write as _;

/// `x` rounded to `decimals` places, as the number a user would type: the value returned is
/// exactly the one the written text parses back to, so every check the generator makes on it
/// is a check of the file.
pub(crate) fn dec(x: f64, decimals: usize) -> f64 {
    let s = format!("{x:.decimals$}");
    // a formatted finite f64 always parses back; fall back to x for a non-finite input
    s.parse::<f64>().map_or(x, |v| v + 0.0)
}

/// A TOML float: the shortest text that parses back to `x`, always with a decimal point.
pub(crate) fn num(x: f64) -> String {
    let x = x + 0.0; // no "-0"
    let mut s = format!("{x}");
    if !s.contains(['.', 'e', 'E']) {
        s.push_str(".0");
    }
    s
}

/// `[a, b, c]` of floats.
pub(crate) fn list(xs: &[f64]) -> String {
    let items: Vec<String> = xs.iter().map(|&x| num(x)).collect();
    format!("[{}]", items.join(", "))
}

/// `["a", "b"]` of strings.
pub(crate) fn names(xs: &[String]) -> String {
    let items: Vec<String> = xs.iter().map(|x| format!("\"{x}\"")).collect();
    format!("[{}]", items.join(", "))
}

/// `text` broken at spaces into lines of at most `width` characters (a longer word stays whole).
pub(crate) fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split(' ') {
        if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    lines.push(line);
    lines
}

/// A value of an attack's own key.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Value {
    Num(f64),
    Str(String),
    List(Vec<f64>),
}

impl Value {
    fn text(&self) -> String {
        match self {
            Value::Num(x) => num(*x),
            Value::Str(s) => format!("\"{s}\""),
            Value::List(xs) => list(xs),
        }
    }
}

/// An obstacle's shape, in the world file's terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Shape {
    /// `cuboid`, half extents \[m\].
    Cuboid([f64; 3]),
    /// `cylinder` standing on the floor.
    Cylinder { radius: f64, half_height: f64 },
    /// `ball` lying on the floor.
    Ball { radius: f64 },
}

/// One `[[obstacles]]` entry.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Obstacle {
    pub name: String,
    pub position: [f64; 3],
    /// Yaw \[rad\]; written as `rpy` only when non-zero.
    pub yaw: f64,
    pub shape: Shape,
}

/// One `[[sensors]]` entry; `None` keys are left out.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct Sensor {
    pub name: String,
    pub measures: &'static str,
    pub noise_std: Option<f64>,
    pub bias: Option<f64>,
    pub bias_walk_std: Option<f64>,
    pub rate_hz: Option<f64>,
    pub dropout_prob: Option<f64>,
    pub ticks_per_rev: Option<u32>,
    pub from_wheels: Option<[String; 2]>,
    pub gyro: Option<String>,
    /// A trailing comment on the `name` line.
    pub comment: Option<String>,
}

/// The one `[[attacks]]` entry.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Attack {
    pub kind: &'static str,
    pub channels: Vec<String>,
    pub start: f64,
    pub end: Option<f64>,
    pub keys: Vec<(&'static str, Value)>,
}

/// Everything a generated world file says.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct WorldText {
    pub header: Vec<String>,
    pub name: String,
    pub duration: f64,
    pub seed: u64,
    pub urdf: String,
    pub start: [f64; 3],
    pub input_limit: Option<f64>,
    pub goal: [f64; 2],
    pub goal_radius: f64,
    pub obstacles: Vec<Obstacle>,
    /// Moving obstacles with their `motion` text (issue #51).
    pub movers: Vec<(Obstacle, String)>,
    /// `[environment] map`, relative to the file's directory.
    pub map: Option<String>,
    pub sensors: Vec<Sensor>,
    pub patterns: Vec<(String, Vec<String>)>,
    pub attack: Attack,
}

impl WorldText {
    /// The TOML text.
    pub fn render(&self) -> String {
        let mut s = String::new();
        // `write!` into a String cannot fail
        macro_rules! w {
            ($($a:tt)*) => {{
                let _ = writeln!(s, $($a)*);
            }};
        }
        for line in self.header.iter().flat_map(|l| wrap(l, 98)) {
            w!("# {line}");
        }
        w!("name = \"{}\"", self.name);
        w!("duration = {}", num(self.duration));
        w!("seed = {}", self.seed);
        w!("");
        w!("[robot]");
        w!("urdf = \"{}\"", self.urdf);
        w!(
            "start = {{ x = {}, y = {}, theta = {} }}",
            num(self.start[0]),
            num(self.start[1]),
            num(self.start[2])
        );
        if let Some(l) = self.input_limit {
            w!("");
            w!("[control]");
            w!("input_limit = {}", num(l));
        }
        w!("");
        w!("[goal]");
        w!("center = {}", list(&self.goal));
        w!("radius = {}", num(self.goal_radius));
        if let Some(m) = &self.map {
            w!("");
            w!("[environment]");
            w!("map = \"{m}\"");
        }
        let all = self
            .obstacles
            .iter()
            .map(|o| (o, None))
            .chain(self.movers.iter().map(|(o, m)| (o, Some(m))));
        for (o, motion) in all {
            w!("");
            w!("[[obstacles]]");
            w!("name = \"{}\"", o.name);
            w!("position = {}", list(&o.position));
            if o.yaw != 0.0 {
                w!("rpy = {}", list(&[0.0, 0.0, o.yaw]));
            }
            match o.shape {
                Shape::Cuboid(h) => {
                    w!(
                        "shape = {{ kind = \"cuboid\", half_extents = {} }}",
                        list(&h)
                    )
                }
                Shape::Cylinder {
                    radius,
                    half_height,
                } => w!(
                    "shape = {{ kind = \"cylinder\", radius = {}, half_height = {} }}",
                    num(radius),
                    num(half_height)
                ),
                Shape::Ball { radius } => {
                    w!("shape = {{ kind = \"ball\", radius = {} }}", num(radius))
                }
            }
            if let Some(m) = motion {
                w!("motion = {m}");
            }
        }
        for c in &self.sensors {
            w!("");
            w!("[[sensors]]");
            match &c.comment {
                Some(com) => w!("name = \"{}\"  # {com}", c.name),
                None => w!("name = \"{}\"", c.name),
            }
            w!("measures = \"{}\"", c.measures);
            let opt = |key: &str, v: Option<f64>| v.map(|v| format!("{key} = {}", num(v)));
            let lines = [
                opt("noise_std", c.noise_std),
                opt("bias", c.bias),
                opt("bias_walk_std", c.bias_walk_std),
                opt("rate_hz", c.rate_hz),
                opt("dropout_prob", c.dropout_prob),
                c.ticks_per_rev.map(|n| format!("ticks_per_rev = {n}")),
                c.from_wheels
                    .as_ref()
                    .map(|[l, r]| format!("from_wheels = [\"{l}\", \"{r}\"]")),
                c.gyro.as_ref().map(|g| format!("gyro = \"{g}\"")),
            ];
            for l in lines.into_iter().flatten() {
                w!("{l}");
            }
        }
        for (name, channels) in &self.patterns {
            w!("");
            w!("[[fault_patterns]]");
            w!("name = \"{name}\"");
            w!("channels = {}", names(channels));
        }
        let a = &self.attack;
        w!("");
        w!("[[attacks]]");
        w!("kind = \"{}\"", a.kind);
        w!("channels = {}", names(&a.channels));
        w!("start = {}", num(a.start));
        if let Some(e) = a.end {
            w!("end = {}", num(e));
        }
        for (k, v) in &a.keys {
            w!("{k} = {}", v.text());
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_lines_wrap_at_spaces() {
        let lines = wrap("aaa bbb ccc ddd", 7);
        assert_eq!(lines, vec!["aaa bbb", "ccc ddd"]);
        assert_eq!(wrap("a-very-long-word x", 4), vec!["a-very-long-word", "x"]);
    }

    #[test]
    fn numbers_are_written_as_typed_and_read_back_exactly() {
        assert_eq!(num(dec(0.1 + 0.2, 2)), "0.3");
        assert_eq!(num(dec(2.0, 2)), "2.0");
        assert_eq!(num(dec(-0.0001, 2)), "0.0");
        assert_eq!(num(1e6), "1000000.0");
        assert_eq!(num(-1.25), "-1.25");
        assert_eq!(num(dec(0.0001 * 3.0, 6)), "0.0003");
        for x in [0.425, 1.0 / 3.0, 2.675, -7.125] {
            let v = dec(x, 3);
            assert_eq!(num(v).parse::<f64>().ok(), Some(v), "{x}");
        }
    }
}
