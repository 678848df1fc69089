//! Collada scene graphs: where each `<instance_geometry>` of a `.dae` file sits.
//!
//! mesh-loader 0.1.13 (which reads the geometry) composes a node's transform with its
//! parents' in the wrong order (child · parent instead of parent · child), keeps one transform
//! per geometry however many nodes instance it, applies the document's `<unit>` before the
//! nodes' transforms and ignores `<instance_node>`: the house's `mailbox.dae` (a parent that
//! rotates and scales, a child that translates) landed 24.8 m from its pose. Here the scene
//! graph is read with roxmltree and composed as COLLADA 1.4 specifies (§5 "Transform
//! elements": a node's transforms post-multiply in document order, a child's frame is its
//! parent's times its own); mesh-loader reads only the geometry libraries, and each instance's
//! vertices are placed by its node's matrix and then scaled by the document's unit.
//!
//! `<up_axis>` is reported, not applied: Gazebo's Collada loader ignores it, so files shipped
//! with Gazebo worlds have data that looks right with Z up whatever they declare (see
//! [`ColladaScene::up_axis`]).

use std::collections::HashMap;

use nalgebra::{Matrix4, Rotation3, Unit, Vector3};

/// Deepest chain of `<instance_node>` references followed (a cycle stops here).
const MAX_INSTANCE_DEPTH: usize = 32;

/// One `<instance_geometry>` in the scene: which geometry, under which node, placed how.
#[derive(Debug, Clone)]
pub struct GeometryInstance {
    /// The geometry's `id` (without `#`).
    pub geometry: String,
    /// The `name` (else `id`) of every node from the scene root to this instance.
    pub nodes: Vec<String>,
    /// The instance's transform from geometry coordinates to the file's root frame, in the
    /// file's units (the [`ColladaScene::unit`] is applied after it).
    pub transform: Matrix4<f64>,
}

/// What the scene graph says about a Collada document.
#[derive(Debug, Clone)]
pub struct ColladaScene {
    /// `<asset><unit meter>` (default 1): metres per file unit.
    pub unit: f64,
    /// `<asset><up_axis>` as declared (`Z_UP`, `Y_UP`, `X_UP`), if declared.
    pub up_axis: Option<String>,
    /// The geometry instances of the scene (empty when the file has no visual scene).
    pub instances: Vec<GeometryInstance>,
    /// Geometry `name` attributes by `id`.
    pub geometry_names: HashMap<String, String>,
    /// What could not be honoured (a `<skew>`, an unresolved reference), for the user.
    pub warnings: Vec<String>,
    /// The document without `<library_visual_scenes>` and `<scene>` (line numbers kept), for
    /// the geometry reader: every geometry comes out untransformed and in file units.
    pub geometry_text: String,
}

fn elements<'a, 'i>(
    n: roxmltree::Node<'a, 'i>,
) -> impl Iterator<Item = roxmltree::Node<'a, 'i>> + 'a {
    n.children().filter(|c| c.is_element())
}

fn child<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    elements(n).find(|c| c.tag_name().name() == tag)
}

/// The numbers of an element's text; an error names the element and its line.
fn numbers(
    doc: &roxmltree::Document,
    n: roxmltree::Node,
    count: usize,
) -> Result<Vec<f64>, String> {
    let line = doc.text_pos_at(n.range().start).row;
    let text = n.text().unwrap_or("");
    let v: Result<Vec<f64>, _> = text.split_whitespace().map(str::parse::<f64>).collect();
    match v {
        Ok(v) if v.len() == count && v.iter().all(|x| x.is_finite()) => Ok(v),
        _ => Err(format!(
            "line {line}: <{}> expects {count} finite numbers, found {:?}",
            n.tag_name().name(),
            text.trim()
        )),
    }
}

/// The matrix of one transform element (`None` for an element that is not a transform).
fn transform_of(
    doc: &roxmltree::Document,
    n: roxmltree::Node,
    warnings: &mut Vec<String>,
) -> Result<Option<Matrix4<f64>>, String> {
    let line = doc.text_pos_at(n.range().start).row;
    Ok(Some(match n.tag_name().name() {
        "matrix" => Matrix4::from_row_slice(&numbers(doc, n, 16)?),
        "translate" => {
            let t = numbers(doc, n, 3)?;
            Matrix4::new_translation(&Vector3::new(t[0], t[1], t[2]))
        }
        "scale" => {
            let s = numbers(doc, n, 3)?;
            Matrix4::new_nonuniform_scaling(&Vector3::new(s[0], s[1], s[2]))
        }
        "rotate" => {
            let r = numbers(doc, n, 4)?;
            let axis = Vector3::new(r[0], r[1], r[2]);
            if axis.norm() < 1e-12 {
                warnings.push(format!(
                    "line {line}: <rotate> has a zero axis; read as no rotation"
                ));
                Matrix4::identity()
            } else {
                Rotation3::from_axis_angle(&Unit::new_normalize(axis), r[3].to_radians())
                    .to_homogeneous()
            }
        }
        "lookat" => lookat(&numbers(doc, n, 9)?, line)?,
        "skew" => {
            warnings.push(format!(
                "line {line}: <skew> is not supported; read as no transform"
            ));
            Matrix4::identity()
        }
        _ => return Ok(None),
    }))
}

/// `<lookat>` eye, interest, up: the frame at the eye whose −z looks at the interest point and
/// whose +y is the up direction made orthogonal to it.
fn lookat(v: &[f64], line: u32) -> Result<Matrix4<f64>, String> {
    let eye = Vector3::new(v[0], v[1], v[2]);
    let dir = Vector3::new(v[3], v[4], v[5]) - eye;
    let up = Vector3::new(v[6], v[7], v[8]);
    let x = dir.cross(&up);
    if dir.norm() < 1e-12 || x.norm() < 1e-12 {
        return Err(format!(
            "line {line}: <lookat> needs an interest point away from the eye and an up vector \
             not along the view direction"
        ));
    }
    let z = -dir.normalize();
    let x = x.normalize();
    let y = z.cross(&x);
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 1>(0, 0).copy_from(&x);
    m.fixed_view_mut::<3, 1>(0, 1).copy_from(&y);
    m.fixed_view_mut::<3, 1>(0, 2).copy_from(&z);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&eye);
    Ok(m)
}

/// Walks the scene graph.
struct Walker<'a, 'i> {
    doc: &'a roxmltree::Document<'i>,
    by_id: HashMap<&'a str, roxmltree::Node<'a, 'i>>,
    instances: Vec<GeometryInstance>,
    warnings: Vec<String>,
}

impl<'a, 'i> Walker<'a, 'i> {
    /// `node` under a parent frame `parent`, `depth` instance references deep.
    fn node(
        &mut self,
        node: roxmltree::Node<'a, 'i>,
        parent: &Matrix4<f64>,
        path: &[String],
        depth: usize,
    ) -> Result<(), String> {
        let mut local = Matrix4::identity();
        for c in elements(node) {
            if let Some(m) = transform_of(self.doc, c, &mut self.warnings)? {
                local *= m;
            }
        }
        let frame = parent * local;
        let mut path = path.to_vec();
        path.push(
            node.attribute("name")
                .or_else(|| node.attribute("id"))
                .unwrap_or("")
                .to_string(),
        );
        for c in elements(node) {
            let line = self.doc.text_pos_at(c.range().start).row;
            match c.tag_name().name() {
                "node" => self.node(c, &frame, &path, depth)?,
                "instance_geometry" => {
                    let url = c.attribute("url").unwrap_or("");
                    self.instances.push(GeometryInstance {
                        geometry: url.trim_start_matches('#').to_string(),
                        nodes: path.clone(),
                        transform: frame,
                    });
                }
                "instance_node" => {
                    let url = c.attribute("url").unwrap_or("").trim_start_matches('#');
                    match self.by_id.get(url).copied() {
                        Some(target) if depth < MAX_INSTANCE_DEPTH => {
                            self.node(target, &frame, &path, depth + 1)?
                        }
                        Some(_) => {
                            return Err(format!(
                                "line {line}: <instance_node> references nest more than \
                                 {MAX_INSTANCE_DEPTH} deep (a cycle?)"
                            ))
                        }
                        None => self.warnings.push(format!(
                            "line {line}: <instance_node url=\"#{url}\"> names no node; skipped"
                        )),
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }
}

/// The scene graph of a Collada document. `None` when `text` is not a Collada document.
pub fn scene(text: &str) -> Result<Option<ColladaScene>, String> {
    if !text.contains("COLLADA") {
        return Ok(None);
    }
    let opts = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..roxmltree::ParsingOptions::default()
    };
    let doc = roxmltree::Document::parse_with_options(text, opts).map_err(|e| e.to_string())?;
    let root = doc.root_element();
    if root.tag_name().name() != "COLLADA" {
        return Ok(None);
    }
    let asset = child(root, "asset");
    let unit = match asset.and_then(|a| child(a, "unit")) {
        Some(u) => {
            let meter = u.attribute("meter").unwrap_or("1");
            match meter.trim().parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => v,
                _ => {
                    return Err(format!(
                        "line {}: <unit meter=\"{meter}\"> expects a positive number of metres",
                        doc.text_pos_at(u.range().start).row
                    ))
                }
            }
        }
        None => 1.0,
    };
    let up_axis = asset
        .and_then(|a| child(a, "up_axis"))
        .and_then(|u| u.text())
        .map(|t| t.trim().to_string());
    let by_id: HashMap<&str, roxmltree::Node> = root
        .descendants()
        .filter(|n| n.is_element() && n.tag_name().name() == "node")
        .filter_map(|n| n.attribute("id").map(|id| (id, n)))
        .collect();
    let geometry_names = root
        .descendants()
        .filter(|n| n.is_element() && n.tag_name().name() == "geometry")
        .filter_map(|n| {
            Some((
                n.attribute("id")?.to_string(),
                n.attribute("name")?.to_string(),
            ))
        })
        .collect();
    let mut walker = Walker {
        doc: &doc,
        by_id,
        instances: Vec::new(),
        warnings: Vec::new(),
    };
    if let Some(vs) = visual_scene(root) {
        for n in elements(vs).filter(|n| n.tag_name().name() == "node") {
            walker.node(n, &Matrix4::identity(), &[], 0)?;
        }
    }
    let mut cut: Vec<std::ops::Range<usize>> = elements(root)
        .filter(|n| matches!(n.tag_name().name(), "library_visual_scenes" | "scene"))
        .map(|n| n.range())
        .collect();
    cut.sort_by_key(|r| r.start);
    let mut geometry_text = String::with_capacity(text.len());
    let mut at = 0;
    for r in cut {
        geometry_text.push_str(&text[at..r.start]);
        geometry_text.extend(text[r.clone()].chars().filter(|&c| c == '\n'));
        at = r.end;
    }
    geometry_text.push_str(&text[at..]);
    Ok(Some(ColladaScene {
        unit,
        up_axis,
        instances: walker.instances,
        geometry_names,
        warnings: walker.warnings,
        geometry_text,
    }))
}

/// The visual scene `<scene><instance_visual_scene url>` names, else the first one.
fn visual_scene<'a, 'i>(root: roxmltree::Node<'a, 'i>) -> Option<roxmltree::Node<'a, 'i>> {
    let lib = child(root, "library_visual_scenes")?;
    let named = child(root, "scene")
        .and_then(|s| child(s, "instance_visual_scene"))
        .and_then(|i| i.attribute("url"))
        .map(|u| u.trim_start_matches('#').to_string());
    let scenes = || elements(lib).filter(|n| n.tag_name().name() == "visual_scene");
    named
        .and_then(|id| scenes().find(|s| s.attribute("id") == Some(id.as_str())))
        .or_else(|| scenes().next())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(nodes: &str, asset: &str) -> String {
        format!(
            r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset>{asset}</asset>
  <library_geometries><geometry id="g" name="G"><mesh/></geometry></library_geometries>
  <library_nodes><node id="lib"><translate>0 0 5</translate><instance_geometry url="#g"/></node></library_nodes>
  <library_visual_scenes><visual_scene id="s">{nodes}</visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>"##
        )
    }

    fn apply(m: &Matrix4<f64>, p: [f64; 3]) -> [f64; 3] {
        let q = m.transform_point(&nalgebra::Point3::from(p));
        [q.x, q.y, q.z]
    }

    #[test]
    fn parent_transforms_apply_after_the_childs() {
        // The parent rotates +90° about z and scales x by 2; the child translates by (1, 0, 0):
        // the child's origin is at parent · (1, 0, 0) = rotate(2, 0, 0) = (0, 2, 0).
        let text = doc(
            r##"<node name="P"><rotate>0 0 1 90</rotate><scale>2 1 1</scale>
                 <node name="C"><matrix>1 0 0 1 0 1 0 0 0 0 1 0 0 0 0 1</matrix>
                   <instance_geometry url="#g"/></node></node>"##,
            "<unit meter=\"0.5\"/><up_axis>Y_UP</up_axis>",
        );
        let s = scene(&text).unwrap().unwrap();
        assert_eq!(s.instances.len(), 1);
        assert_eq!(s.instances[0].nodes, ["P", "C"]);
        let p = apply(&s.instances[0].transform, [0.0, 0.0, 0.0]);
        assert!((p[0]).abs() < 1e-12 && (p[1] - 2.0).abs() < 1e-12, "{p:?}");
        assert_eq!(s.unit, 0.5);
        assert_eq!(s.up_axis.as_deref(), Some("Y_UP"));
        assert!(!s.geometry_text.contains("visual_scene"));
        assert_eq!(s.geometry_text.lines().count(), text.lines().count());
    }

    #[test]
    fn instance_nodes_and_lookat_are_followed() {
        let s = scene(&doc(
            r##"<node name="A"><lookat>1 2 3  1 2 0  0 1 0</lookat><instance_node url="#lib"/></node>"##,
            "",
        ))
        .unwrap()
        .unwrap();
        assert_eq!(s.instances.len(), 1);
        // Looking down −z from (1, 2, 3): the local z axis is world +z, so local (0, 0, 5) is
        // world (1, 2, 8).
        let p = apply(&s.instances[0].transform, [0.0, 0.0, 0.0]);
        assert!((p[0] - 1.0).abs() < 1e-12 && (p[1] - 2.0).abs() < 1e-12);
        assert!((p[2] - 8.0).abs() < 1e-12, "{p:?}");
    }

    #[test]
    fn bad_numbers_name_the_line() {
        let e = scene(&doc(r#"<node><translate>1 x 2</translate></node>"#, "")).unwrap_err();
        assert!(e.starts_with("line 6: <translate> expects 3"), "{e}");
    }
}
