//! Reading one glTF primitive into a [`Mesh`], after checking every accessor it uses.
//!
//! The `gltf` crate's reader returns `None` for an accessor that reaches past its buffer
//! view (so a missing index list silently became "no indices", and an out-of-range POSITION
//! "no POSITION"), and trusts the component type and stride (a debug assertion, or garbage
//! in a release build). So each accessor is checked first, with checked arithmetic:
//! its type, its stride, its last byte inside its buffer view, the view inside the
//! loaded buffer. Sparse accessors are refused (their reader panics on malformed index
//! types). Errors name the attribute; the caller adds the mesh and primitive.

use filtrace_core::{Vec2, Vec3};
use gltf::accessor::{DataType, Dimensions};

use crate::obj::is_degenerate;
use crate::types::{MaterialId, Mesh};

/// What an accessor may hold, per the glTF 2.0 specification (section 3.7.2.1).
#[derive(Clone, Copy)]
pub(crate) enum Kind {
    Indices,
    Vec3F32,
    TexCoord,
    /// Animation key times.
    ScalarF32,
    /// Animation rotation keys: floats or normalised integers.
    Rotation,
}

/// Checks that `acc` (used as `what`) has an allowed type and lies inside its data.
pub(crate) fn check_accessor(
    acc: &gltf::Accessor,
    buffers: &[gltf::buffer::Data],
    what: &str,
    kind: Kind,
) -> Result<(), String> {
    let at = format!("{what} (accessor {})", acc.index());
    let (dims, ty) = (acc.dimensions(), acc.data_type());
    let type_ok = match kind {
        Kind::Indices => {
            dims == Dimensions::Scalar && matches!(ty, DataType::U8 | DataType::U16 | DataType::U32)
        }
        Kind::Vec3F32 => dims == Dimensions::Vec3 && ty == DataType::F32,
        Kind::TexCoord => {
            dims == Dimensions::Vec2
                && (ty == DataType::F32 || (acc.normalized() && matches!(ty, DataType::U8 | DataType::U16)))
        }
        Kind::ScalarF32 => dims == Dimensions::Scalar && ty == DataType::F32,
        Kind::Rotation => {
            let ints = matches!(ty, DataType::I8 | DataType::U8 | DataType::I16 | DataType::U16);
            dims == Dimensions::Vec4 && (ty == DataType::F32 || (acc.normalized() && ints))
        }
    };
    if !type_ok {
        return Err(format!("{at}: type {dims:?} of {ty:?} is not allowed here"));
    }
    if acc.sparse().is_some() {
        return Err(format!("{at}: sparse accessors are not supported"));
    }
    if acc.count() == 0 {
        return Err(format!("{at}: count is 0"));
    }
    let Some(view) = acc.view() else {
        return Err(format!("{at}: no bufferView"));
    };
    let elem = acc.size();
    let stride = view.stride().unwrap_or(elem);
    if stride < elem {
        return Err(format!("{at}: byteStride {stride} is smaller than one element ({elem} bytes)"));
    }
    let end = (acc.count() - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(acc.offset()))
        .and_then(|x| x.checked_add(elem));
    if !matches!(end, Some(end) if end <= view.length()) {
        let (count, offset, v) = (acc.count(), acc.offset(), view.index());
        let len = view.length();
        return Err(format!(
            "{at}: {count} elements from byte {offset} (stride {stride}) run past the end of bufferView {v} ({len} bytes)"
        ));
    }
    let data_len = buffers.get(view.buffer().index()).map_or(0, |d| d.len());
    match view.offset().checked_add(view.length()) {
        Some(vend) if vend <= data_len => Ok(()),
        _ => Err(format!(
            "{at}: bufferView {} (bytes {} + {}) runs past the end of buffer {} ({data_len} bytes)",
            view.index(),
            view.offset(),
            view.length(),
            view.buffer().index()
        )),
    }
}

/// Reads a triangle primitive; degenerate triangles are skipped and counted in `skipped`.
pub(crate) fn read_primitive(
    prim: &gltf::Primitive,
    buffers: &[gltf::buffer::Data],
    material: MaterialId,
    name: &str,
    skipped: &mut usize,
) -> Result<Mesh, String> {
    let pos_acc = prim.get(&gltf::Semantic::Positions).ok_or("primitive without POSITION")?;
    check_accessor(&pos_acc, buffers, "POSITION", Kind::Vec3F32)?;
    if let Some(acc) = prim.indices() {
        check_accessor(&acc, buffers, "indices", Kind::Indices)?;
    }
    let normals = prim.get(&gltf::Semantic::Normals);
    if let Some(acc) = &normals {
        check_accessor(acc, buffers, "NORMAL", Kind::Vec3F32)?;
    }
    let uvs = prim.get(&gltf::Semantic::TexCoords(0));
    if let Some(acc) = &uvs {
        check_accessor(acc, buffers, "TEXCOORD_0", Kind::TexCoord)?;
    }
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    // Checked above, so the reader cannot refuse; stay an error rather than a panic anyway.
    let unreadable = |what: &str| format!("{what}: accessor could not be read");
    let positions: Vec<Vec3> =
        reader.read_positions().ok_or_else(|| unreadable("POSITION"))?.map(Vec3::from).collect();
    let n = positions.len();
    let flat: Vec<u32> = match (prim.indices(), reader.read_indices()) {
        (None, _) => (0..n as u32).collect(),
        (Some(_), Some(i)) => i.into_u32().collect(),
        (Some(_), None) => return Err(unreadable("indices")),
    };
    let mut mesh = triangles(&flat, &positions, material, name, skipped)?;
    if normals.is_some() {
        let ns: Vec<Vec3> = reader
            .read_normals()
            .ok_or_else(|| unreadable("NORMAL"))?
            .map(|v| Vec3::from(v).normalize_or_zero())
            .collect();
        if ns.len() == n && ns.iter().all(|v| v.is_finite() && *v != Vec3::ZERO) {
            mesh.normals = ns;
        }
    }
    if uvs.is_some() {
        let uv: Vec<Vec2> = reader
            .read_tex_coords(0)
            .ok_or_else(|| unreadable("TEXCOORD_0"))?
            .into_f32()
            .map(|[u, v]| Vec2::new(u, 1.0 - v))
            .collect();
        if uv.len() == n {
            mesh.uvs = uv;
        }
    }
    mesh.positions = positions;
    Ok(mesh)
}

/// The mesh's triangles from a flat index list (every index checked against the vertex count).
fn triangles(
    flat: &[u32],
    positions: &[Vec3],
    material: MaterialId,
    name: &str,
    skipped: &mut usize,
) -> Result<Mesh, String> {
    let n = positions.len();
    if !flat.chunks_exact(3).remainder().is_empty() {
        return Err(format!("index count {} is not a multiple of 3", flat.len()));
    }
    let mut mesh = Mesh { name: name.to_string(), ..Mesh::default() };
    for t in flat.chunks_exact(3) {
        let t = [t[0], t[1], t[2]];
        if let Some(&bad) = t.iter().find(|&&i| i as usize >= n) {
            return Err(format!("vertex index {bad} out of range ({n} vertices)"));
        }
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || is_degenerate(t.map(|i| positions[i as usize])) {
            *skipped += 1;
            continue;
        }
        mesh.indices.push(t);
        mesh.material_ids.push(material);
    }
    Ok(mesh)
}
