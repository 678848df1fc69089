//! ROS occupancy maps (`environment.map`): map_server's YAML and its PGM or PNG image, read as
//! nav2's `map_io` reads them, turned into one obstacle — a signed distance field for the
//! barrier and merged boxes for the physics.
//!
//! # The file
//! ```yaml
//! image: map.pgm            # relative to the YAML file
//! resolution: 0.05          # m per cell
//! origin: [-10.0, -10.0, 0.0]   # pose of the lower-left cell's lower-left corner: x, y [m], yaw [rad]
//! negate: 0
//! occupied_thresh: 0.65
//! free_thresh: 0.196
//! mode: trinary             # optional: trinary (default), scale or raw
//! ```
//! A pixel's shade s ∈ [0, 1] (its grey value over the maximum; the mean of the colour channels
//! of an RGB PNG) gives the occupancy probability p = 1 − s (p = s with `negate`). `trinary`
//! and `scale`: occupied when p > occupied_thresh, free when p < free_thresh, unknown otherwise
//! (in `scale`, a pixel that is not opaque is unknown too; the intermediate costs `scale` gives
//! nav2 are neither free nor occupied here, so they are unknown). `raw`: the value round(255·s)
//! is the occupancy in percent, 0–100 (p = value / 100, then the thresholds as above); above
//! 100 it is unknown. Image row 0 is the top of the map; cell (i, j) (column i, row j counted
//! from the bottom) has its centre at origin + R(yaw)·((i + ½)·res, (j + ½)·res).
//!
//! # Limits
//! A map has at most [`MAX_MAP_CELLS`] cells, a resolution in [[`MIN_RESOLUTION`],
//! [`MAX_RESOLUTION`]] m and an origin within [`MAX_ORIGIN`] m: the image's size is read from
//! its header and refused before any cell is allocated.
//!
//! # The distance field
//! Blocked cells are the occupied ones and, unless `environment.unknown = "free"`, the unknown
//! ones; beyond the map's edge is blocked or free likewise. The obstacle is the union of the
//! blocked cells' squares. The exact Euclidean distance transform of Felzenszwalb and
//! Huttenlocher ("Distance Transforms of Sampled Functions", Theory of Computing 8, 2012:
//! the lower envelope of parabolas, one pass along rows and one along columns, O(cells)) gives
//! at each cell centre the distance D to the nearest blocked centre (free cells) or the nearest
//! free centre (blocked cells). The node values s = D − res/√2 (free) and s = −D (blocked) are
//! lower bounds of the signed distance sd to the union of squares, and
//! sd_map(p) = bilinear(s)(p) − res/√2 is a lower bound of sd(p) everywhere (sd is
//! 1-Lipschitz and the bilinear weights put their nodes within res/√2 of p on average), with
//! 0 ≤ sd(p) − sd_map(p) ≤ 3·res/√2 (2.12 cells) on the map and one cell around it: **the grid's error is in the barrier, on the
//! safe side**. Beyond the map's edge the value continues with slope −1 from the nearest edge
//! point (a lower bound again). The gradient is the bilinear interpolation of central
//! differences of s at the nodes, so it is continuous and the lifted barrier
//! d + k∇d·v has no jumps; its derivative (the Hessian) is bounded cell by cell, and the bounds
//! G on ‖∇sd_map‖ and κ on ‖∇²sd_map‖ over the cells that reach free space
//! ([`MapField::gradient_bound`], [`MapField::curvature_bound`]) are computed once. A lookup
//! costs the same on any map (four nodes and their neighbours).
//!
//! One file (about 1,000 lines): map_server's format — the YAML keys, the PGM and PNG readers,
//! the thresholds and modes — with each key's validation, so that an error names the key it
//! read; what is made of the grid lives beside it (the outline pieces in `outline`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix2, Translation3, UnitQuaternion, Vector2};
use parry3d::shape::SharedShape;
use yaml_rust2::{Yaml, YamlLoader};

/// `environment.unknown`: how a map's unknown cells (neither free nor occupied) are treated.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum UnknownCells {
    /// Unknown cells are obstacles (the robot does not drive where the map has not seen).
    #[default]
    Obstacle,
    /// Unknown cells are free space.
    Free,
}

/// The most cells a map may have: 16·10⁶ (4,000 × 4,000, 200 m square at 5 cm; about 0.3 GB
/// while the distance field is built).
pub const MAX_MAP_CELLS: u64 = 16_000_000;
/// The finest resolution accepted \[m\].
pub const MIN_RESOLUTION: f64 = 1e-3;
/// The coarsest resolution accepted \[m\].
pub const MAX_RESOLUTION: f64 = 10.0;
/// The largest |x| or |y| of a map's origin \[m\] (parry's f32 keeps millimetres there).
pub const MAX_ORIGIN: f64 = 1e4;
/// The largest YAML file read \[bytes\].
const MAX_YAML_BYTES: u64 = 1 << 20;
/// Half the height of the boxes the physics gets for blocked cells \[m\] (they stand on z = 0).
pub const WALL_HALF_HEIGHT: f64 = 0.5;

/// What is wrong with a map; each names the file and the key or what was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapError {
    /// A file that cannot be read.
    #[error("{file}: cannot be read: {message}")]
    Read {
        /// The file.
        file: String,
        /// Why.
        message: String,
    },
    /// Not YAML.
    #[error("{file}: line {line}, column {column}: not YAML: {message}")]
    Yaml {
        /// The file.
        file: String,
        /// 1-based.
        line: usize,
        /// 1-based.
        column: usize,
        /// What the YAML reader said.
        message: String,
    },
    /// A key missing or out of range.
    #[error("{file}: `{key}` must be {expected}, got {got}")]
    Key {
        /// The file.
        file: String,
        /// The key.
        key: String,
        /// What is expected.
        expected: String,
        /// What was found.
        got: String,
    },
    /// The image named by `image` cannot be read or decoded.
    #[error("{file}: `image` names {path}: {message}")]
    Image {
        /// The YAML file.
        file: String,
        /// The image path as resolved.
        path: String,
        /// Why.
        message: String,
    },
}

/// How pixel values become cells (`mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Occupied, free or unknown by the thresholds.
    Trinary,
    /// As trinary, and a pixel that is not opaque is unknown.
    Scale,
    /// The value is the occupancy in percent.
    Raw,
}

/// The YAML's keys, read and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct MapYaml {
    /// The image, resolved against the YAML file's directory.
    pub image: PathBuf,
    /// Cell size \[m\].
    pub resolution: f64,
    /// x \[m\], y \[m\], yaw \[rad\] of the lower-left cell's lower-left corner.
    pub origin: [f64; 3],
    /// Whether white is occupied.
    pub negate: bool,
    /// Above this occupancy probability a cell is occupied.
    pub occupied_thresh: f64,
    /// Below this occupancy probability a cell is free.
    pub free_thresh: f64,
    /// `mode`.
    pub mode: Mode,
}

/// One cell of the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cell {
    /// Known free.
    Free,
    /// Known occupied.
    Occupied,
    /// Neither.
    Unknown,
}

impl Cell {
    /// Whether the robot must keep out of the cell.
    pub fn blocked(self, unknown: UnknownCells) -> bool {
        match self {
            Cell::Occupied => true,
            Cell::Unknown => unknown == UnknownCells::Obstacle,
            Cell::Free => false,
        }
    }
}

/// An occupancy map: cells in rows from the bottom (the origin's side) up.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    /// Cells per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Cell size \[m\].
    pub resolution: f64,
    /// x \[m\], y \[m\], yaw \[rad\] of the lower-left cell's lower-left corner.
    pub origin: [f64; 3],
    /// Row-major, row 0 at the bottom.
    pub cells: Vec<Cell>,
}

fn key_err(file: &Path, key: &str, expected: &str, got: String) -> MapError {
    MapError::Key {
        file: file.display().to_string(),
        key: key.to_string(),
        expected: expected.to_string(),
        got,
    }
}

/// A YAML scalar as a number (integers too), else `None`.
fn number(y: &Yaml) -> Option<f64> {
    match y {
        Yaml::Integer(i) => Some(*i as f64),
        Yaml::Real(_) => y.as_f64(),
        _ => None,
    }
}

fn shown(y: &Yaml) -> String {
    match y {
        Yaml::Real(s) | Yaml::String(s) => format!("{s:?}"),
        Yaml::Integer(i) => i.to_string(),
        Yaml::Boolean(b) => b.to_string(),
        Yaml::Array(a) => format!("a list of {} items", a.len()),
        Yaml::Hash(_) => "a mapping".into(),
        Yaml::Null | Yaml::BadValue => "nothing".into(),
        Yaml::Alias(_) => "an alias".into(),
    }
}

/// Reads the file at `path` whole, refusing one longer than `limit` bytes.
fn read_limited(path: &Path, limit: u64) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let f = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mut bytes = Vec::new();
    f.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| e.to_string())?;
    if bytes.len() as u64 > limit {
        return Err(format!("longer than {limit} bytes"));
    }
    Ok(bytes)
}

impl MapYaml {
    /// Reads and checks map_server's YAML at `path`.
    pub fn load(path: &Path) -> Result<Self, MapError> {
        let file = path.display().to_string();
        let bytes = read_limited(path, MAX_YAML_BYTES).map_err(|message| MapError::Read {
            file: file.clone(),
            message,
        })?;
        let text = String::from_utf8(bytes).map_err(|e| MapError::Read {
            file: file.clone(),
            message: format!("not UTF-8 text ({e})"),
        })?;
        let docs = YamlLoader::load_from_str(&text).map_err(|e| MapError::Yaml {
            file: file.clone(),
            line: e.marker().line(),
            column: e.marker().col() + 1,
            message: e.info().to_string(),
        })?;
        let base = path.parent().unwrap_or_else(|| Path::new("."));
        Self::from_yaml(path, base, docs.first().unwrap_or(&Yaml::Null))
    }

    /// The keys of the document `doc` of the file `path`, images resolved against `base`.
    fn from_yaml(path: &Path, base: &Path, doc: &Yaml) -> Result<Self, MapError> {
        let Yaml::Hash(h) = doc else {
            return Err(key_err(
                path,
                "(top level)",
                "a mapping of map_server's keys",
                shown(doc),
            ));
        };
        let known = [
            "image",
            "resolution",
            "origin",
            "negate",
            "occupied_thresh",
            "free_thresh",
            "mode",
        ];
        for k in h.keys() {
            match k.as_str() {
                Some(name) if known.contains(&name) => {}
                _ => {
                    return Err(key_err(
                        path,
                        &shown(k),
                        &format!("one of map_server's keys ({})", known.join(", ")),
                        "an unknown key".into(),
                    ))
                }
            }
        }
        let get = |k: &str| h.get(&Yaml::String(k.into()));
        let image = match get("image") {
            Some(Yaml::String(s)) if !s.trim().is_empty() => base.join(s),
            other => {
                let got = other.map_or("nothing".into(), shown);
                return Err(key_err(
                    path,
                    "image",
                    "the image file's name (PGM or PNG)",
                    got,
                ));
            }
        };
        let num = |k: &str, expected: &str, ok: &dyn Fn(f64) -> bool| {
            let y = get(k);
            match y.and_then(number) {
                Some(v) if v.is_finite() && ok(v) => Ok(v),
                _ => Err(key_err(
                    path,
                    k,
                    expected,
                    y.map_or("nothing".into(), shown),
                )),
            }
        };
        let resolution = num(
            "resolution",
            &format!("the cell size in metres, in [{MIN_RESOLUTION}, {MAX_RESOLUTION}]"),
            &|v| (MIN_RESOLUTION..=MAX_RESOLUTION).contains(&v),
        )?;
        let origin = Self::origin(path, get("origin"))?;
        let negate = match get("negate") {
            None => false,
            Some(Yaml::Integer(0)) | Some(Yaml::Boolean(false)) => false,
            Some(Yaml::Integer(1)) | Some(Yaml::Boolean(true)) => true,
            Some(y) => return Err(key_err(path, "negate", "0 or 1", shown(y))),
        };
        let prob = "a probability in [0, 1]";
        let occupied_thresh = num("occupied_thresh", prob, &|v| (0.0..=1.0).contains(&v))?;
        let free_thresh = num("free_thresh", prob, &|v| (0.0..=1.0).contains(&v))?;
        if free_thresh > occupied_thresh {
            return Err(key_err(
                path,
                "free_thresh",
                &format!("at most occupied_thresh ({occupied_thresh})"),
                free_thresh.to_string(),
            ));
        }
        let mode = match get("mode").map(|y| (y, y.as_str())) {
            None | Some((_, Some("trinary"))) => Mode::Trinary,
            Some((_, Some("scale"))) => Mode::Scale,
            Some((_, Some("raw"))) => Mode::Raw,
            Some((y, _)) => {
                return Err(key_err(path, "mode", "trinary, scale or raw", shown(y)));
            }
        };
        Ok(Self {
            image,
            resolution,
            origin,
            negate,
            occupied_thresh,
            free_thresh,
            mode,
        })
    }

    fn origin(path: &Path, y: Option<&Yaml>) -> Result<[f64; 3], MapError> {
        let expected = format!("[x, y, yaw]: metres within ±{MAX_ORIGIN} and radians");
        let got = || y.map_or("nothing".into(), shown);
        let Some(Yaml::Array(a)) = y else {
            return Err(key_err(path, "origin", &expected, got()));
        };
        let v: Vec<f64> = a.iter().filter_map(number).collect();
        if a.len() != 3 || v.len() != 3 {
            return Err(key_err(path, "origin", &expected, got()));
        }
        for (i, name) in ["x", "y"].iter().enumerate() {
            if !(v[i].is_finite() && v[i].abs() <= MAX_ORIGIN) {
                return Err(key_err(
                    path,
                    &format!("origin ({name})"),
                    &expected,
                    v[i].to_string(),
                ));
            }
        }
        if !v[2].is_finite() || v[2].abs() > 1e3 {
            return Err(key_err(path, "origin (yaw)", &expected, v[2].to_string()));
        }
        Ok([v[0], v[1], v[2]])
    }

    /// The cell a pixel of shade `s` ∈ [0, 1] (and opacity) becomes (module docs).
    pub fn classify(&self, shade: f64, opaque: bool) -> Cell {
        let by_thresholds = |p: f64| {
            if p > self.occupied_thresh {
                Cell::Occupied
            } else if p < self.free_thresh {
                Cell::Free
            } else {
                Cell::Unknown
            }
        };
        match self.mode {
            Mode::Trinary | Mode::Scale => {
                if self.mode == Mode::Scale && !opaque {
                    return Cell::Unknown;
                }
                by_thresholds(if self.negate { shade } else { 1.0 - shade })
            }
            Mode::Raw => {
                let value = (shade * 255.0).round();
                if value <= 100.0 {
                    by_thresholds(value / 100.0)
                } else {
                    Cell::Unknown
                }
            }
        }
    }
}

/// An image that could not be decoded: too large for a map, or malformed.
enum ImageError {
    TooLarge(u64, u64),
    Bad(String),
}

fn size_ok(w: u64, h: u64) -> Result<(), ImageError> {
    if w == 0 || h == 0 || w.saturating_mul(h) > MAX_MAP_CELLS {
        return Err(ImageError::TooLarge(w, h));
    }
    Ok(())
}

/// Netpbm greyscale (P2 plain, P5 raw; Jef Poskanzer's `pgm` format): the header's whitespace-
/// separated tokens with `#` comments, then the samples (one byte each for maxval < 256, two
/// big-endian bytes otherwise). Cells from the top row down, classified by `classify`.
fn decode_pgm(bytes: &[u8], classify: &dyn Fn(f64, bool) -> Cell) -> Result<Image, ImageError> {
    let bad = |m: &str| ImageError::Bad(m.to_string());
    let mut pos = 2;
    let token = |pos: &mut usize| -> Option<u64> {
        loop {
            match bytes.get(*pos)? {
                b'#' => {
                    while *bytes.get(*pos)? != b'\n' {
                        *pos += 1;
                    }
                }
                c if c.is_ascii_whitespace() => *pos += 1,
                _ => break,
            }
        }
        let start = *pos;
        while bytes.get(*pos).is_some_and(|c| c.is_ascii_digit()) {
            *pos += 1;
        }
        std::str::from_utf8(&bytes[start..*pos]).ok()?.parse().ok()
    };
    let plain = match bytes.get(..2) {
        Some(b"P2") => true,
        Some(b"P5") => false,
        _ => return Err(bad("not a PGM (P2 or P5) or PNG image")),
    };
    let header = "a PGM header: width, height, maxval (1 to 65535)";
    let w = token(&mut pos).ok_or_else(|| bad(header))?;
    let h = token(&mut pos).ok_or_else(|| bad(header))?;
    let maxval = token(&mut pos)
        .filter(|m| (1..=65535).contains(m))
        .ok_or_else(|| bad(header))?;
    size_ok(w, h)?;
    let n = (w * h) as usize;
    let mut cells = Vec::with_capacity(n);
    let m = maxval as f64;
    if plain {
        for _ in 0..n {
            let v = token(&mut pos)
                .filter(|v| *v <= maxval)
                .ok_or_else(|| bad(&format!("{n} samples from 0 to {maxval} after the header")))?;
            cells.push(classify(v as f64 / m, true));
        }
    } else {
        // Exactly one whitespace byte after maxval.
        let data = bytes.get(pos + 1..).unwrap_or(&[]);
        let bps = if maxval < 256 { 1 } else { 2 };
        if data.len() < n * bps {
            return Err(bad(&format!(
                "the P5 data ends after {} of its {n} samples",
                data.len() / bps
            )));
        }
        for k in 0..n {
            let v = if bps == 1 {
                data[k] as u64
            } else {
                u16::from_be_bytes([data[2 * k], data[2 * k + 1]]) as u64
            };
            cells.push(classify(v.min(maxval) as f64 / m, true));
        }
    }
    Ok(Image {
        width: w as usize,
        height: h as usize,
        cells,
    })
}

/// PNG through the `png` crate: palette and low bit depths expanded, 16 bits stripped to 8;
/// the shade of a colour pixel is the mean of its channels, alpha 255 is opaque.
fn decode_png(bytes: &[u8], classify: &dyn Fn(f64, bool) -> Cell) -> Result<Image, ImageError> {
    let bad = |e: png::DecodingError| ImageError::Bad(format!("not a readable PNG: {e}"));
    let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    // The header's size is checked below before any pixel buffer exists; the decoder's own
    // allocation limit stays generous enough for the largest accepted map in RGBA.
    dec.set_limits(png::Limits {
        bytes: (MAX_MAP_CELLS as usize) * 4 + (1 << 20),
    });
    let mut reader = dec.read_info().map_err(bad)?;
    let (w, h) = (reader.info().width as u64, reader.info().height as u64);
    size_ok(w, h)?;
    let size = reader
        .output_buffer_size()
        .ok_or(ImageError::TooLarge(w, h))?;
    let mut buf = vec![0u8; size];
    let info = reader.next_frame(&mut buf).map_err(bad)?;
    let channels = info.color_type.samples();
    let (colour, alpha) = match channels {
        1 => (1, false),
        2 => (1, true),
        3 => (3, false),
        _ => (3, true),
    };
    let mut cells = Vec::with_capacity((w * h) as usize);
    for row in buf.chunks(info.line_size).take(h as usize) {
        for px in row.chunks(channels).take(w as usize) {
            let shade =
                px[..colour].iter().map(|&c| c as f64).sum::<f64>() / (255.0 * colour as f64);
            let opaque = !alpha || px[colour] == 255;
            cells.push(classify(shade, opaque));
        }
    }
    Ok(Image {
        width: w as usize,
        height: h as usize,
        cells,
    })
}

/// Decoded cells, top row first.
struct Image {
    width: usize,
    height: usize,
    cells: Vec<Cell>,
}

impl OccupancyGrid {
    /// Loads map_server's YAML at `path` and its image.
    pub fn load(path: &Path) -> Result<Self, MapError> {
        let y = MapYaml::load(path)?;
        Self::from_yaml(path, &y)
    }

    /// The image of `y` (read from the YAML file `path`) read into cells.
    pub fn from_yaml(path: &Path, y: &MapYaml) -> Result<Self, MapError> {
        let img_err = |message: String| MapError::Image {
            file: path.display().to_string(),
            path: y.image.display().to_string(),
            message,
        };
        // A PGM of the largest size at two bytes a sample, plus its header.
        let bytes = read_limited(&y.image, MAX_MAP_CELLS * 8 + 4096)
            .map_err(|m| img_err(format!("cannot be read: {m}")))?;
        let classify = |s: f64, o: bool| y.classify(s, o);
        let decoded = if bytes.starts_with(b"\x89PNG") {
            decode_png(&bytes, &classify)
        } else {
            decode_pgm(&bytes, &classify)
        };
        let img = decoded.map_err(|e| match e {
            ImageError::TooLarge(w, h) => img_err(format!(
                "{w} × {h} cells: a map has at least one and at most {MAX_MAP_CELLS} cells"
            )),
            ImageError::Bad(m) => img_err(m),
        })?;
        // Rows from the bottom up.
        let mut cells = Vec::with_capacity(img.cells.len());
        for row in img.cells.chunks(img.width).rev() {
            cells.extend_from_slice(row);
        }
        Ok(Self {
            width: img.width,
            height: img.height,
            resolution: y.resolution,
            origin: y.origin,
            cells,
        })
    }

    /// The cell in column `i`, row `j` from the bottom.
    pub fn cell(&self, i: usize, j: usize) -> Cell {
        self.cells[j * self.width + i]
    }

    /// The world position \[m\] of a point given in cells from the origin corner.
    pub fn to_world(&self, cx: f64, cy: f64) -> [f64; 2] {
        let (s, c) = self.origin[2].sin_cos();
        let (x, y) = (cx * self.resolution, cy * self.resolution);
        [
            self.origin[0] + c * x - s * y,
            self.origin[1] + s * x + c * y,
        ]
    }

    /// The world position \[m\] of the centre of cell (i, j).
    pub fn cell_centre(&self, i: usize, j: usize) -> [f64; 2] {
        self.to_world(i as f64 + 0.5, j as f64 + 0.5)
    }

    /// The pose of the map frame (origin and yaw) in the world.
    pub fn pose(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.origin[0], self.origin[1], 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, self.origin[2]),
        )
    }

    /// The blocked cells merged into rectangles, in cells: [i0, j0, i1, j1) — runs of a row
    /// joined with the same run of the rows above. When `unknown` cells are obstacles, four
    /// one-cell walls just outside the map close it (beyond its edge is unknown).
    pub fn rectangles(&self, unknown: UnknownCells) -> Vec<[i64; 4]> {
        let mut open: BTreeMap<(usize, usize), usize> = BTreeMap::new();
        let mut done: Vec<[i64; 4]> = Vec::new();
        for j in 0..=self.height {
            let mut runs = Vec::new();
            if j < self.height {
                let mut i = 0;
                while i < self.width {
                    if self.cell(i, j).blocked(unknown) {
                        let a = i;
                        while i < self.width && self.cell(i, j).blocked(unknown) {
                            i += 1;
                        }
                        runs.push((a, i));
                    } else {
                        i += 1;
                    }
                }
            }
            let mut next = BTreeMap::new();
            for run in runs {
                let j0 = open.remove(&run).unwrap_or(j);
                next.insert(run, j0);
            }
            for ((a, b), j0) in std::mem::replace(&mut open, next) {
                done.push([a as i64, j0 as i64, b as i64, j as i64]);
            }
        }
        if unknown == UnknownCells::Obstacle {
            let (w, h) = (self.width as i64, self.height as i64);
            done.extend([
                [-1, -1, w + 1, 0],
                [-1, h, w + 1, h + 1],
                [-1, 0, 0, h],
                [w, 0, w + 1, h],
            ]);
        }
        done
    }

    /// The blocked cells as one compound of boxes standing on z = 0, in the map frame (see
    /// [`OccupancyGrid::pose`]); `None` when no cell is blocked.
    pub fn compound(&self, unknown: UnknownCells) -> Option<SharedShape> {
        let r = self.resolution;
        let parts: Vec<_> = self
            .rectangles(unknown)
            .into_iter()
            .map(|[i0, j0, i1, j1]| {
                let (hx, hy) = ((i1 - i0) as f64 * r / 2.0, (j1 - j0) as f64 * r / 2.0);
                let c = Isometry3::translation(
                    i0 as f64 * r + hx,
                    j0 as f64 * r + hy,
                    WALL_HALF_HEIGHT,
                );
                (
                    parry3d::math::Pose::from(c.cast::<f32>()),
                    SharedShape::cuboid(hx as f32, hy as f32, WALL_HALF_HEIGHT as f32),
                )
            })
            .collect();
        (!parts.is_empty()).then(|| SharedShape::compound(parts))
    }
}

/// A large finite stand-in for "no site" in the distance transform (keeps the arithmetic free
/// of ∞ − ∞).
const FAR: f64 = 1e30;

/// One row of the squared Euclidean distance transform of a sampled function `f` (Felzenszwalb
/// & Huttenlocher 2012, §2): `out[q] = min_p (q − p)² + f[p]`, the lower envelope of the
/// parabolas rooted at each p, found in one sweep. `v` (n) and `z` (n + 1) are scratch.
fn edt_1d(f: &[f64], out: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    let sq = |q: usize| (q * q) as f64;
    let mut k = 0;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in 1..n {
        let cut = |p: usize| ((f[q] + sq(q)) - (f[p] + sq(p))) / (2.0 * (q - p) as f64);
        let mut s = cut(v[k]);
        // z[0] = −∞ ends the loop at k = 0 at the latest (s is finite).
        while s <= z[k] {
            k -= 1;
            s = cut(v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, o) in out.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let d = q as f64 - v[k] as f64;
        *o = d * d + f[v[k]];
    }
}

/// The exact squared Euclidean distance \[cells²\] from each cell of an `nx` × `ny` grid
/// (row-major) to the nearest cell with `site` set; `FAR` or more when there is none.
pub fn squared_distance_transform(site: &[bool], nx: usize, ny: usize) -> Vec<f64> {
    let mut d: Vec<f64> = site.iter().map(|&s| if s { 0.0 } else { FAR }).collect();
    let m = nx.max(ny);
    let (mut f, mut out, mut v, mut z) = (
        vec![0.0; m],
        vec![0.0; m],
        vec![0usize; m],
        vec![0.0; m + 1],
    );
    for j in 0..ny {
        let row = &mut d[j * nx..(j + 1) * nx];
        f[..nx].copy_from_slice(row);
        edt_1d(&f[..nx], &mut out[..nx], &mut v, &mut z);
        row.copy_from_slice(&out[..nx]);
    }
    for i in 0..nx {
        for j in 0..ny {
            f[j] = d[j * nx + i];
        }
        edt_1d(&f[..ny], &mut out[..ny], &mut v, &mut z);
        for j in 0..ny {
            d[j * nx + i] = out[j];
        }
    }
    d
}

/// The map's signed distance field (module docs): node values at the cell centres of the map
/// padded by one cell of "beyond the edge" on each side.
#[derive(Clone)]
pub struct MapField {
    nx: usize,
    ny: usize,
    res: f64,
    origin: [f64; 2],
    cos: f64,
    sin: f64,
    values: Vec<f64>,
    blocked: Vec<bool>,
    gradient_bound: f64,
    curvature_bound: f64,
}

/// The blocked cell nearest a point ([`MapField::nearest_blocked`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NearestCell {
    /// Column and row from the bottom, in the map's cells; −1 or the width/height for the
    /// blocked rim beyond the map's edge.
    pub cell: (i64, i64),
    /// Its centre in the world \[m\].
    pub centre: [f64; 2],
    /// From the point to the centre \[m\].
    pub distance: f64,
}

impl std::fmt::Debug for MapField {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MapField")
            .field("nodes", &(self.nx, self.ny))
            .field("resolution", &self.res)
            .field("gradient_bound", &self.gradient_bound)
            .field("curvature_bound", &self.curvature_bound)
            .finish()
    }
}

impl MapField {
    /// The field of `grid` with `unknown` cells (and beyond the edge) treated as given.
    pub fn new(grid: &OccupancyGrid, unknown: UnknownCells) -> Self {
        let (nx, ny) = (grid.width + 2, grid.height + 2);
        let outside = Cell::Unknown.blocked(unknown);
        let mut blocked = vec![outside; nx * ny];
        for j in 0..grid.height {
            for i in 0..grid.width {
                blocked[(j + 1) * nx + i + 1] = grid.cell(i, j).blocked(unknown);
            }
        }
        let to_blocked = squared_distance_transform(&blocked, nx, ny);
        let free: Vec<bool> = blocked.iter().map(|b| !b).collect();
        let to_free = squared_distance_transform(&free, nx, ny);
        let res = grid.resolution;
        let cap = (nx + ny) as f64 * res;
        let values = blocked
            .iter()
            .zip(to_blocked.iter().zip(&to_free))
            .map(|(&b, (&db, &df))| {
                let v = if b {
                    -df.sqrt() * res
                } else {
                    db.sqrt() * res - res / std::f64::consts::SQRT_2
                };
                v.clamp(-cap, cap)
            })
            .collect();
        let (sin, cos) = grid.origin[2].sin_cos();
        let mut field = Self {
            nx,
            ny,
            res,
            origin: [grid.origin[0], grid.origin[1]],
            cos,
            sin,
            values,
            blocked,
            gradient_bound: 0.0,
            curvature_bound: 0.0,
        };
        field.bounds();
        field
    }

    /// G and κ over the cells with a node in free space (s ≥ 0): the gradient's norm is a
    /// convex function of the bilinear weights, each Hessian entry affine along the cell, so
    /// their maxima over a cell are at its corners.
    fn bounds(&mut self) {
        let (g, k) = self.bounds_in(0.0, f64::INFINITY);
        self.gradient_bound = g;
        self.curvature_bound = k;
    }

    /// (G, κ) over the cells whose node values reach into [lo, hi] \[m\]: the band of the
    /// field where a barrier's zero level and its neighbourhood lie. O(cells).
    pub fn bounds_in(&self, lo: f64, hi: f64) -> (f64, f64) {
        let (mut g_max, mut k_max) = (0.0f64, 0.0f64);
        for j in 0..self.ny - 1 {
            for i in 0..self.nx - 1 {
                let nodes = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)];
                let vals = nodes.map(|(a, b)| self.value(a, b));
                let top = vals.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v));
                let bottom = vals.iter().fold(f64::INFINITY, |m, v| m.min(*v));
                if top < lo || bottom > hi {
                    continue;
                }
                let g = nodes.map(|(a, b)| self.node_gradient(a, b));
                for gk in &g {
                    g_max = g_max.max(gk.norm());
                }
                for (fx, fy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                    k_max = k_max.max(Self::cell_hessian(&g, fx, fy, self.res).norm());
                }
            }
        }
        (g_max, k_max)
    }

    fn value(&self, i: usize, j: usize) -> f64 {
        self.values[j * self.nx + i]
    }

    /// Central differences of the node values (one-sided at the edge) \[1\], map frame.
    fn node_gradient(&self, i: usize, j: usize) -> Vector2<f64> {
        let d = |lo: f64, hi: f64, span: usize| (hi - lo) / (span as f64 * self.res);
        let (il, ih) = (i.saturating_sub(1), (i + 1).min(self.nx - 1));
        let (jl, jh) = (j.saturating_sub(1), (j + 1).min(self.ny - 1));
        Vector2::new(
            d(self.value(il, j), self.value(ih, j), ih - il),
            d(self.value(i, jl), self.value(i, jh), jh - jl),
        )
    }

    /// The derivative of the bilinearly interpolated gradient at (fx, fy) in a cell whose
    /// corner gradients are `g` (00, 10, 01, 11), symmetrised.
    fn cell_hessian(g: &[Vector2<f64>; 4], fx: f64, fy: f64, res: f64) -> Matrix2<f64> {
        let ddx = ((g[1] - g[0]) * (1.0 - fy) + (g[3] - g[2]) * fy) / res;
        let ddy = ((g[2] - g[0]) * (1.0 - fx) + (g[3] - g[1]) * fx) / res;
        let m = Matrix2::from_columns(&[ddx, ddy]);
        0.5 * (m + m.transpose())
    }

    /// Node coordinates of a world point (node i at the centre of padded cell i).
    fn node_coords(&self, p: [f64; 2]) -> (f64, f64) {
        let (dx, dy) = (p[0] - self.origin[0], p[1] - self.origin[1]);
        let lx = self.cos * dx + self.sin * dy;
        let ly = -self.sin * dx + self.cos * dy;
        (lx / self.res + 0.5, ly / self.res + 0.5)
    }

    /// The lower bound sd_map of the signed distance \[m\] from world point `p` to the blocked
    /// cells, and its gradient (world frame). O(1).
    pub fn signed_distance(&self, p: [f64; 2]) -> (f64, Vector2<f64>) {
        let (u, v) = self.node_coords(p);
        let uq = u.clamp(0.0, (self.nx - 1) as f64);
        let vq = v.clamp(0.0, (self.ny - 1) as f64);
        let beyond = ((u - uq).powi(2) + (v - vq).powi(2)).sqrt() * self.res;
        let i = (uq.floor() as usize).min(self.nx - 2);
        let j = (vq.floor() as usize).min(self.ny - 2);
        let (fx, fy) = (uq - i as f64, vq - j as f64);
        let w = [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ];
        let nodes = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)];
        let mut value = 0.0;
        let mut g = Vector2::zeros();
        for (wk, &(a, b)) in w.iter().zip(&nodes) {
            value += wk * self.value(a, b);
            g += *wk * self.node_gradient(a, b);
        }
        if beyond > 0.0 {
            if u != uq {
                g.x = -(u - uq) * self.res / beyond;
            }
            if v != vq {
                g.y = -(v - vq) * self.res / beyond;
            }
        }
        let value = value - self.res / std::f64::consts::SQRT_2 - beyond;
        let gw = Vector2::new(
            self.cos * g.x - self.sin * g.y,
            self.sin * g.x + self.cos * g.y,
        );
        (value, gw)
    }

    /// The largest amount by which [`MapField::signed_distance`] may fall short of the signed
    /// distance to the blocked cells' squares \[m\]: 3·res/√2 (module docs). Never above it.
    pub fn error_bound(&self) -> f64 {
        3.0 * self.res / std::f64::consts::SQRT_2
    }

    /// G: the largest norm of the interpolated gradient over cells reaching free space.
    pub fn gradient_bound(&self) -> f64 {
        self.gradient_bound
    }

    /// κ: the largest norm of the interpolated gradient's derivative over those cells \[1/m\].
    pub fn curvature_bound(&self) -> f64 {
        self.curvature_bound
    }

    /// The cell size \[m\].
    pub fn resolution(&self) -> f64 {
        self.res
    }

    /// The map cell that holds world point `p`, if it is blocked: (column, row) from the
    /// bottom left, −1 or the width/height for the rim beyond the edge (blocked when unknown
    /// cells are), and beyond that the cell the map's grid would have there. `None` when the
    /// cell is free. Decided by the cell, not by the sign of [`MapField::signed_distance`]
    /// (a lower bound that is negative next to blocked cells too).
    pub fn blocked_cell_at(&self, p: [f64; 2]) -> Option<(i64, i64)> {
        let (u, v) = self.node_coords(p);
        let (i, j) = (u.round() as i64, v.round() as i64);
        let (nx, ny) = (self.nx as i64, self.ny as i64);
        let blocked = if (0..nx).contains(&i) && (0..ny).contains(&j) {
            self.blocked[(j * nx + i) as usize]
        } else {
            // Beyond the padded grid: as its rim (cell 0 of the padding).
            self.blocked[0]
        };
        blocked.then_some((i - 1, j - 1))
    }

    /// The blocked cell whose centre is nearest `p` (world frame), searched ring by ring
    /// outwards from p's cell; `None` when no cell is blocked. For reports (`check`), not for
    /// the control loop: O(distance²) in cells.
    pub fn nearest_blocked(&self, p: [f64; 2]) -> Option<NearestCell> {
        let (u, v) = self.node_coords(p);
        let (ci, cj) = (u.round() as i64, v.round() as i64);
        let (nx, ny) = (self.nx as i64, self.ny as i64);
        let mut best: Option<(f64, i64, i64)> = None;
        for ring in 0..=(nx + ny + ci.abs() + cj.abs()) {
            // A cell of a later ring is at least (ring − 1) cells away.
            if best.is_some_and(|(d, _, _)| d < (ring as f64 - 1.0).max(0.0)) {
                break;
            }
            for a in -ring..=ring {
                for b in -ring..=ring {
                    if a.abs() != ring && b.abs() != ring {
                        continue;
                    }
                    let (i, j) = (ci + a, cj + b);
                    if i < 0 || j < 0 || i >= nx || j >= ny {
                        continue;
                    }
                    if self.blocked[(j * nx + i) as usize] {
                        let d = ((i as f64 - u).powi(2) + (j as f64 - v).powi(2)).sqrt();
                        if best.is_none_or(|(bd, _, _)| d < bd) {
                            best = Some((d, i, j));
                        }
                    }
                }
            }
        }
        best.map(|(d, i, j)| {
            let (lx, ly) = ((i as f64 - 0.5) * self.res, (j as f64 - 0.5) * self.res);
            NearestCell {
                cell: (i - 1, j - 1),
                centre: [
                    self.origin[0] + self.cos * lx - self.sin * ly,
                    self.origin[1] + self.sin * lx + self.cos * ly,
                ],
                distance: d * self.res,
            }
        })
    }
}
