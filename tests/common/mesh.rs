//! Mesh fixtures shared by the root tests (`tests/fuzz.rs`) and the simulator's
//! (`sim/tests/reliability_46.rs`, which includes this file by path): one cube and one ASCII STL
//! writer instead of a copy in each.

/// A cube's 8 corners (half-size `h`, centred on `c`) and its 12 triangles wound outward.
pub fn cube(c: [f64; 3], h: f64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let v = (0..8)
        .map(|i| {
            let s = |b: usize| if i & b != 0 { h } else { -h };
            [c[0] + s(1), c[1] + s(2), c[2] + s(4)]
        })
        .collect();
    let t = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    (v, t)
}

/// The triangles `t` over the vertices `v` as an ASCII STL solid named `name`.
pub fn stl_text(name: &str, v: &[[f64; 3]], t: &[[u32; 3]]) -> String {
    let mut s = format!("solid {name}\n");
    for tri in t {
        s.push_str("facet normal 0 0 0\nouter loop\n");
        for &i in tri {
            let p = v[i as usize];
            s.push_str(&format!("vertex {} {} {}\n", p[0], p[1], p[2]));
        }
        s.push_str("endloop\nendfacet\n");
    }
    s.push_str(&format!("endsolid {name}\n"));
    s
}
