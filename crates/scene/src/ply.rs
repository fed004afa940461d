//! PLY loader (Turk 1994 format): `ascii`, `binary_little_endian` and `binary_big_endian`.
//!
//! Reads the `vertex` element (`x y z`, optional `nx ny nz`, optional `u v` / `s t` /
//! `texture_u texture_v`) and the `face` element (`vertex_indices` or `vertex_index` list;
//! polygons are fan-triangulated). Other elements and properties are skipped. The mesh gets
//! the default grey material. Errors name the file and, for ASCII bodies and headers, the line;
//! binary bodies report the byte offset instead.

use std::path::Path;

use filtrace_core::{Vec2, Vec3};

use crate::error::SceneError;
use crate::obj::is_degenerate;
use crate::types::{Material, Mesh, Scene};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Debug)]
enum Property {
    Scalar { name: String, ty: Scalar },
    List { name: String, count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

/// Loads a PLY file into a scene with one mesh placed once.
pub fn load_ply(path: &Path) -> Result<Scene, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::Io { path: path.to_path_buf(), source: e })?;
    parse_ply(&bytes, path)
}

/// Reads values one at a time from an ASCII or binary body.
struct Body<'a> {
    format: Format,
    data: &'a [u8],
    pos: usize,
    /// ASCII: current line number (1-based, counted over the whole file).
    line: usize,
    tokens: std::vec::IntoIter<&'a str>,
}

impl<'a> Body<'a> {
    /// Moves an ASCII body to the next non-empty line.
    fn next_line(&mut self) -> Result<(), String> {
        loop {
            if self.pos >= self.data.len() {
                return Err("unexpected end of file".into());
            }
            let end = self.data[self.pos..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(self.data.len(), |i| self.pos + i);
            let text =
                std::str::from_utf8(&self.data[self.pos..end]).map_err(|_| "invalid UTF-8".to_string())?;
            self.pos = end + 1;
            self.line += 1;
            let toks: Vec<&'a str> = text.split_whitespace().collect();
            if !toks.is_empty() {
                self.tokens = toks.into_iter();
                return Ok(());
            }
        }
    }

    fn read(&mut self, ty: Scalar) -> Result<f64, String> {
        match self.format {
            Format::Ascii => {
                let tok = self.tokens.next().ok_or("too few values on the line")?;
                tok.parse::<f64>().map_err(|_| format!("cannot parse number '{tok}'"))
            }
            Format::BinaryLe | Format::BinaryBe => {
                let n = ty.size();
                let Some(b) = self.data.get(self.pos..self.pos + n) else {
                    return Err(format!("unexpected end of file at byte {}", self.pos));
                };
                self.pos += n;
                let mut a = [0u8; 8];
                a[..n].copy_from_slice(b);
                if self.format == Format::BinaryBe {
                    a[..n].reverse();
                }
                Ok(match ty {
                    Scalar::I8 => a[0] as i8 as f64,
                    Scalar::U8 => a[0] as f64,
                    Scalar::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
                    Scalar::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
                    Scalar::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
                    Scalar::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
                    Scalar::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
                    Scalar::F64 => f64::from_le_bytes(a),
                })
            }
        }
    }

    fn where_(&self) -> Option<usize> {
        (self.format == Format::Ascii).then_some(self.line)
    }
}

/// Parses PLY bytes; `path` names the file in errors.
pub fn parse_ply(bytes: &[u8], path: &Path) -> Result<Scene, SceneError> {
    let header = parse_header(bytes, path)?;
    let mut body = Body {
        format: header.format,
        data: bytes,
        pos: header.pos,
        line: header.lines,
        tokens: Vec::new().into_iter(),
    };
    let data = read_elements(&mut body, &header, path)?;
    build_scene(data, path)
}

/// The header: format, elements with their properties, where the body starts (byte) and
/// how many lines the header has.
struct Header {
    format: Format,
    elements: Vec<Element>,
    pos: usize,
    lines: usize,
}

/// Reads the ASCII header lines up to `end_header`.
fn parse_header(bytes: &[u8], path: &Path) -> Result<Header, SceneError> {
    let err = |line: Option<usize>, m: String| SceneError::parse(path, line, m);
    let mut pos = 0;
    let mut line_no = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(nl) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(err(Some(line_no + 1), "header without end_header".into()));
        };
        let text = String::from_utf8_lossy(&bytes[pos..pos + nl]).trim().to_string();
        pos += nl + 1;
        line_no += 1;
        let toks: Vec<&str> = text.split_whitespace().collect();
        if line_no == 1 {
            if text != "ply" {
                return Err(err(Some(1), "not a PLY file (first line must be 'ply')".into()));
            }
            continue;
        }
        match toks.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                format = Some(match toks.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::BinaryLe,
                    Some("binary_big_endian") => Format::BinaryBe,
                    f => return Err(err(Some(line_no), format!("unknown format {f:?}"))),
                });
            }
            Some("element") => {
                let (Some(name), Some(count)) =
                    (toks.get(1), toks.get(2).and_then(|c| c.parse::<usize>().ok()))
                else {
                    return Err(err(Some(line_no), format!("bad element line '{text}'")));
                };
                elements.push(Element { name: name.to_string(), count, props: Vec::new() });
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(err(Some(line_no), "property before any element".into()));
                };
                el.props.push(
                    parse_property(&toks)
                        .ok_or_else(|| err(Some(line_no), format!("bad property line '{text}'")))?,
                );
            }
            Some("end_header") => break,
            Some(other) => return Err(err(Some(line_no), format!("unknown header line '{other}'"))),
        }
    }
    let format = format.ok_or_else(|| err(None, "header has no format line".into()))?;
    Ok(Header { format, elements, pos, lines: line_no })
}

/// A `property` line's tokens: `property TYPE NAME` or `property list COUNT ITEM NAME`.
fn parse_property(toks: &[&str]) -> Option<Property> {
    if toks.get(1) == Some(&"list") {
        let count = toks.get(2).and_then(|t| Scalar::parse(t))?;
        let item = toks.get(3).and_then(|t| Scalar::parse(t))?;
        let name = toks.get(4)?.to_string();
        Some(Property::List { name, count, item })
    } else {
        let ty = toks.get(1).and_then(|t| Scalar::parse(t))?;
        Some(Property::Scalar { name: toks.get(2)?.to_string(), ty })
    }
}

/// What the body's `vertex` and `face` elements hold; faces with the line they were read
/// from (ASCII) for errors.
#[derive(Default)]
struct Elements {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    uvs: Vec<Vec2>,
    polygons: Vec<(Vec<i64>, Option<usize>)>,
}

/// Reads every element of the body; keeps the vertices' position, normal and uv and the
/// faces' vertex lists, skips the rest.
fn read_elements(body: &mut Body, header: &Header, path: &Path) -> Result<Elements, SceneError> {
    let err = |line: Option<usize>, m: String| SceneError::parse(path, line, m);
    let format = header.format;
    let mut out = Elements::default();
    for el in &header.elements {
        let is_vertex = el.name == "vertex";
        let is_face = el.name == "face";
        let col = |names: &[&str]| {
            el.props
                .iter()
                .position(|p| matches!(p, Property::Scalar { name, .. } if names.contains(&name.as_str())))
        };
        let (ix, iy, iz) = (col(&["x"]), col(&["y"]), col(&["z"]));
        let (inx, iny, inz) = (col(&["nx"]), col(&["ny"]), col(&["nz"]));
        let (iu, iv) = (col(&["u", "s", "texture_u"]), col(&["v", "t", "texture_v"]));
        if is_vertex && (ix.is_none() || iy.is_none() || iz.is_none()) {
            return Err(err(Some(header.lines), "vertex element lacks x, y or z".into()));
        }
        let has_n = inx.is_some() && iny.is_some() && inz.is_some();
        let has_uv = iu.is_some() && iv.is_some();
        let mut vals = vec![0.0f64; el.props.len()];
        for _ in 0..el.count {
            if format == Format::Ascii {
                body.next_line().map_err(|m| err(body.where_(), m))?;
            }
            let face = read_item(body, el, is_face, &mut vals).map_err(|m| err(body.where_(), m))?;
            if is_vertex {
                let g = |i: Option<usize>| vals[i.unwrap_or(0)] as f32;
                out.positions.push(Vec3::new(g(ix), g(iy), g(iz)));
                if has_n {
                    out.normals.push(Vec3::new(g(inx), g(iny), g(inz)));
                }
                if has_uv {
                    out.uvs.push(Vec2::new(g(iu), g(iv)));
                }
            }
            if let Some(f) = face {
                out.polygons.push((f, body.where_()));
            }
            if format == Format::Ascii && body.tokens.len() > 0 {
                return Err(err(body.where_(), format!("too many values for element '{}'", el.name)));
            }
        }
    }
    Ok(out)
}

/// One item of element `el`: its scalar properties into `vals`, and the vertex list when
/// the element is a face (`is_face`) and the list its `vertex_indices`.
fn read_item(
    body: &mut Body,
    el: &Element,
    is_face: bool,
    vals: &mut [f64],
) -> Result<Option<Vec<i64>>, String> {
    let mut face = None;
    for (k, p) in el.props.iter().enumerate() {
        match p {
            Property::Scalar { ty, .. } => vals[k] = body.read(*ty)?,
            Property::List { name, count, item } => {
                let n = body.read(*count)?;
                if !(0.0..=1e6).contains(&n) {
                    return Err(format!("bad list length {n}"));
                }
                let mut items = Vec::with_capacity(n as usize);
                for _ in 0..n as usize {
                    items.push(body.read(*item)? as i64);
                }
                if is_face && (name == "vertex_indices" || name == "vertex_index") {
                    face = Some(items);
                }
            }
        }
    }
    Ok(face)
}

/// One mesh with the default grey material: faces fan-triangulated, degenerate triangles
/// skipped (counted in the scene's stats), normals kept only when all are usable.
fn build_scene(data: Elements, path: &Path) -> Result<Scene, SceneError> {
    let Elements { positions, normals, uvs, polygons } = data;
    let mut scene = Scene {
        name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        ..Scene::default()
    };
    let mat = scene.add_material(Material::default_grey());
    let mut mesh = Mesh { name: scene.name.clone(), ..Mesh::default() };
    let nv = positions.len() as i64;
    for (poly, line) in polygons {
        if poly.len() < 3 {
            return Err(SceneError::parse(
                path,
                line,
                format!("face with {} vertices (at least 3 needed)", poly.len()),
            ));
        }
        if let Some(&bad) = poly.iter().find(|&&i| i < 0 || i >= nv) {
            return Err(SceneError::parse(
                path,
                line,
                format!("vertex index {bad} out of range ({nv} vertices)"),
            ));
        }
        for k in 1..poly.len() - 1 {
            let t = [poly[0] as u32, poly[k] as u32, poly[k + 1] as u32];
            let p = t.map(|i| positions[i as usize]);
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || is_degenerate(p) {
                scene.stats.degenerate_triangles_skipped += 1;
                continue;
            }
            mesh.indices.push(t);
            mesh.material_ids.push(mat);
        }
    }
    if normals.iter().all(|n| n.is_finite() && n.length_squared() > 0.0) {
        mesh.normals = normals.into_iter().map(Vec3::normalize).collect();
    }
    mesh.positions = positions;
    mesh.uvs = uvs;
    scene.add_mesh(mesh);
    Ok(scene)
}
