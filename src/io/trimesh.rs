//! Meshes rendered as triangles (issue 57): a PLY or Wavefront OBJ mesh
//! read whole, with its vertex normals where it has them, and every
//! triangle checked before any is used (a degenerate, non-finite or
//! out-of-range one is a one-line error naming the file and the face).

use super::{IoError, IoErrorKind, Mesh, read_file};
use crate::primitive::Triangle;
use glam::{DVec3, Vec3};
use std::path::Path;

/// A mesh to render as triangles.
#[derive(Clone, Debug, PartialEq)]
pub struct TriangleMesh {
    /// Positions (offsets from `mesh.origin`, read in f64 and re-centred)
    /// and fan-triangulated faces.
    pub mesh: Mesh,
    /// Per triangle, the unit normals at its three corners, where the file
    /// gives them; `[Vec3::ZERO; 3]` for a triangle without (or with a
    /// zero-length one): it shades with its face normal. `None`: the file
    /// has no normals.
    pub normals: Option<Vec<[Vec3; 3]>>,
}

/// Peak bytes a rendered triangle takes: 293 measured with the octree, 278
/// with Embree (peak resident of `render` of a scene of the bunny mesh's
/// 69,666 triangles at 64x48, less that of the 60-triangle table of
/// `scenes/hybrid.toml`: the file read whole, its vertices and faces, the
/// placed triangles, their normals and the accelerator), rounded up.
pub const BYTES_PER_TRIANGLE: u64 = 320;

/// The face count a PLY file's header declares (`element face N`), read
/// from its first 64 KiB alone; `None` for another file or no such line.
fn ply_face_count(path: &Path) -> Option<u64> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path)
        .ok()?
        .take(1 << 16)
        .read_to_end(&mut head)
        .ok()?;
    if !head.starts_with(b"ply") {
        return None;
    }
    let text = String::from_utf8_lossy(&head);
    text.lines()
        .take_while(|l| l.trim() != "end_header")
        .find_map(|l| match l.split_whitespace().collect::<Vec<_>>()[..] {
            ["element", "face", n] => n.parse().ok(),
            _ => None,
        })
}

/// Reads a mesh to render as triangles: an OBJ file (`.obj`, or text
/// starting with an OBJ statement) or a PLY file with a `face` element.
/// Polygons are fan-triangulated.
///
/// # Errors
/// One line naming the file: it cannot be read, a PLY header declares
/// more faces than the memory left holds ([`BYTES_PER_TRIANGLE`] each),
/// it is malformed, has no faces, or a face has an out-of-range or negative index, a non-finite
/// vertex or normal, or spans no area (its face number, counted from 0 in
/// the file's order, and for OBJ its line).
pub fn read_triangles(path: &Path) -> Result<TriangleMesh, IoError> {
    read_triangles_within(path, None)
}

/// [`read_triangles`] within `cap` bytes (`--max-memory`) as well as the
/// machine's bounds: a PLY mesh is refused from its header's face count,
/// an OBJ mesh while it is read, its triangles so far counted every 65,536
/// faces, so that a mesh over the cap is refused before it is all in
/// memory.
///
/// # Errors
/// As [`read_triangles`]; over `cap`, one line naming the file and the
/// faces counted.
pub fn read_triangles_within(path: &Path, cap: Option<u64>) -> Result<TriangleMesh, IoError> {
    if let Some(faces) = ply_face_count(path) {
        crate::memory::check_within(
            &format!("holding its {faces} faces as triangles"),
            faces.saturating_mul(BYTES_PER_TRIANGLE),
            cap,
        )
        .map_err(|e| IoError::new(path, IoErrorKind::Memory(e)))?;
    }
    if let (Some(cap), Ok(meta)) = (cap, std::fs::metadata(path)) {
        crate::memory::check_within("reading the file whole", meta.len(), Some(cap))
            .map_err(|e| IoError::new(path, IoErrorKind::Memory(e)))?;
    }
    let bytes = read_file(path)?;
    let obj = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    parse_triangles_within(&bytes, obj, cap).map_err(|kind| IoError::new(path, kind))
}

/// [`read_triangles`] on a file's bytes; `obj` when the name says OBJ
/// (else a PLY file, or OBJ text recognised by its first statement).
///
/// # Errors
/// As [`read_triangles`], without the file's name.
pub fn parse_triangles(bytes: &[u8], obj: bool) -> Result<TriangleMesh, IoErrorKind> {
    parse_triangles_within(bytes, obj, None)
}

/// [`parse_triangles`] with an OBJ mesh's triangles checked against `cap`
/// (and the machine's bounds) every 65,536 faces while it is read.
///
/// # Errors
/// As [`read_triangles_within`], without the file's name.
pub fn parse_triangles_within(
    bytes: &[u8],
    obj: bool,
    cap: Option<u64>,
) -> Result<TriangleMesh, IoErrorKind> {
    let ply = bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n");
    let (mesh, normals, face_of, line_of) = if !ply && (obj || looks_like_obj(bytes)) {
        let o = parse_obj(bytes, cap)?;
        (o.mesh, o.normals, o.face_of, Some(o.line_of))
    } else {
        let m = super::parse_mesh_full(bytes)?;
        let normals = match m.normals {
            None => None,
            Some(n) => {
                if let Some((i, _)) = m
                    .mesh
                    .triangles
                    .iter()
                    .flatten()
                    .map(|&i| (i, n[i as usize]))
                    .find(|(_, v)| !v.is_finite())
                {
                    return Err(IoErrorKind::Data(format!(
                        "vertex {i} has a non-finite normal"
                    )));
                }
                Some(
                    m.mesh
                        .triangles
                        .iter()
                        .map(|t| corners(t.map(|i| n[i as usize])))
                        .collect(),
                )
            }
        };
        (m.mesh, normals, m.face_of, None)
    };
    for (k, t) in mesh.triangles.iter().enumerate() {
        let tri = Triangle {
            v: t.map(|i| mesh.positions[i as usize]),
        };
        if !tri.is_proper() {
            // Vertices as the file counts them: OBJ from 1, PLY from 0.
            let (line, from) = line_of
                .as_ref()
                .map_or((String::new(), 0), |l| (format!(" (line {})", l[k]), 1));
            return Err(IoErrorKind::Data(format!(
                "face {}{line} is degenerate: its vertices {}, {} and {} span no area",
                face_of[k],
                t[0] + from,
                t[1] + from,
                t[2] + from
            )));
        }
    }
    Ok(TriangleMesh { mesh, normals })
}

/// Unit corner normals, or zeros when one is of zero length.
fn corners(n: [Vec3; 3]) -> [Vec3; 3] {
    let u = n.map(Vec3::normalize_or_zero);
    if u.contains(&Vec3::ZERO) {
        [Vec3::ZERO; 3]
    } else {
        u
    }
}

/// True when the first statement of the text (past blank lines and
/// comments) is one of OBJ's.
fn looks_like_obj(bytes: &[u8]) -> bool {
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(4096)]);
    head.lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .and_then(|l| l.split_whitespace().next())
        .is_some_and(|w| {
            matches!(
                w,
                "v" | "vn" | "vt" | "f" | "o" | "g" | "s" | "mtllib" | "usemtl"
            )
        })
}

/// An OBJ file's mesh, with each triangle's face (from 0) and line.
struct ObjRead {
    mesh: Mesh,
    normals: Option<Vec<[Vec3; 3]>>,
    face_of: Vec<u32>,
    line_of: Vec<u32>,
}

/// Reads OBJ's `v`, `vn` and `f` statements (others are ignored); face
/// corners `v`, `v/t`, `v//n` or `v/t/n`, indices from 1 or, negative,
/// back from the last one read.
fn parse_obj(bytes: &[u8], cap: Option<u64>) -> Result<ObjRead, IoErrorKind> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| IoErrorKind::Data(format!("an OBJ file must be UTF-8 text: {e}")))?;
    let mut world: Vec<DVec3> = Vec::new();
    let mut vn: Vec<Vec3> = Vec::new();
    // Per triangle: vertex indices, normal indices (if every corner has one).
    let mut tris: Vec<([u32; 3], Option<[u32; 3]>)> = Vec::new();
    let (mut face_of, mut line_of) = (Vec::new(), Vec::new());
    let mut faces = 0u32;
    for (ln, line) in text.lines().enumerate() {
        let ln = ln + 1;
        let mut words = line.split_whitespace();
        let Some(key) = words.next() else { continue };
        let bad = |what: &str| IoErrorKind::Data(format!("line {ln}: {what}"));
        let xyz = |words: std::str::SplitWhitespace<'_>| -> Result<DVec3, IoErrorKind> {
            let v: Vec<f64> = words
                .take(3)
                .map(str::parse::<f64>)
                .collect::<Result<_, _>>()
                .map_err(|_| bad(&format!("`{key}` needs three numbers")))?;
            match v[..] {
                [x, y, z] => Ok(DVec3::new(x, y, z)),
                _ => Err(bad(&format!("`{key}` needs three numbers"))),
            }
        };
        match key {
            "v" => world.push(xyz(words)?),
            "vn" => {
                let n = xyz(words)?.as_vec3();
                if !n.is_finite() {
                    return Err(bad(&format!("normal {} is not finite", vn.len() + 1)));
                }
                vn.push(n);
            }
            "f" => {
                let face = faces;
                faces += 1;
                let mut corners = Vec::new();
                for w in words {
                    let mut parts = w.split('/');
                    let index = |s: Option<&str>, count: usize, what: &str| {
                        resolve_index(s, count)
                            .map_err(|e| bad(&format!("face {face}: {what} {e}")))
                    };
                    let v = index(parts.next(), world.len(), "vertex")?
                        .ok_or_else(|| bad(&format!("face {face}: a corner without a vertex")))?;
                    let _texture = parts.next();
                    let n = index(parts.next(), vn.len(), "normal")?;
                    corners.push((v, n));
                }
                if corners.len() < 3 {
                    return Err(bad(&format!(
                        "face {face} has {} corners, fewer than three",
                        corners.len()
                    )));
                }
                for k in 1..corners.len() - 1 {
                    let c = [corners[0], corners[k], corners[k + 1]];
                    let n = match c.map(|(_, n)| n) {
                        [Some(a), Some(b), Some(c)] => Some([a, b, c]),
                        _ => None,
                    };
                    tris.push((c.map(|(v, _)| v), n));
                    face_of.push(face);
                    line_of.push(ln as u32);
                }
                if faces.is_multiple_of(1 << 16) {
                    let n = tris.len() as u64;
                    crate::memory::check_within(
                        &format!("holding its first {faces} faces as {n} triangles"),
                        n.saturating_mul(BYTES_PER_TRIANGLE),
                        cap,
                    )
                    .map_err(IoErrorKind::Memory)?;
                }
            }
            _ => {}
        }
    }
    if tris.is_empty() {
        return Err(IoErrorKind::NoPoints(
            "the mesh has no triangles (no `f` statement)".into(),
        ));
    }
    if let Some((k, i)) = tris
        .iter()
        .enumerate()
        .flat_map(|(k, t)| t.0.iter().map(move |&i| (k, i)))
        .find(|&(_, i)| !world[i as usize].is_finite())
    {
        return Err(IoErrorKind::Data(format!(
            "line {}: face {} uses vertex {}, which has a non-finite coordinate",
            line_of[k],
            face_of[k],
            i + 1
        )));
    }
    // Re-centred in f64 before single precision, as a PLY mesh is.
    let origin = crate::data::robust_centre_size(world.len(), |i| world[i])
        .map_or(DVec3::ZERO, |(centre, _)| centre);
    let positions = world.iter().map(|p| (*p - origin).as_vec3()).collect();
    let with_normals = tris.iter().any(|t| t.1.is_some());
    let normals = with_normals.then(|| {
        tris.iter()
            .map(|t| t.1.map_or([Vec3::ZERO; 3], |n| corners_of(&vn, n)))
            .collect()
    });
    Ok(ObjRead {
        mesh: Mesh {
            positions,
            triangles: tris.iter().map(|t| t.0).collect(),
            origin,
        },
        normals,
        face_of,
        line_of,
    })
}

fn corners_of(vn: &[Vec3], n: [u32; 3]) -> [Vec3; 3] {
    corners(n.map(|i| vn[i as usize]))
}

/// An OBJ index (`None` when absent or empty) made 0-based against the
/// `count` items read so far.
fn resolve_index(s: Option<&str>, count: usize) -> Result<Option<u32>, String> {
    let Some(s) = s.filter(|s| !s.is_empty()) else {
        return Ok(None);
    };
    let i: i64 = s.parse().map_err(|_| format!("index `{s}` is not an integer"))?;
    let n = count as i64;
    let at = match i {
        0 => return Err("index 0 (OBJ counts from 1)".into()),
        i if i > 0 => i - 1,
        i => n + i,
    };
    if at < 0 || at >= n {
        return Err(format!("{i} out of range: {n} read so far"));
    }
    u32::try_from(at)
        .map(Some)
        .map_err(|_| format!("index {i} is too large"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        match parse_triangles(text.as_bytes(), true) {
            Err(e) => IoError::new(Path::new("m.obj"), e).to_string(),
            Ok(m) => panic!("read {m:?}"),
        }
    }

    #[test]
    fn obj_faces_normals_and_negative_indices() {
        let m = parse_triangles(
            b"# a quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 2\n\
              f 1//1 2//1 3//1 4//1\nf -4 -2 -1\n",
            true,
        )
        .unwrap();
        assert_eq!(m.mesh.triangles, [[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
        let n = m.normals.unwrap();
        assert_eq!(n[0], [Vec3::Z; 3], "unit");
        assert_eq!(n[2], [Vec3::ZERO; 3], "no normals: the face's");
        // Recognised by its text without the extension.
        assert!(parse_triangles(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", false).is_ok());
    }

    #[test]
    fn bad_obj_faces_are_one_line_errors_naming_the_face() {
        let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        for (text, expect) in [
            (format!("{tri}f 1 2 4\n"), "line 4: face 0: vertex 4 out of range: 3 read so far"),
            (format!("{tri}f 1 2 0\n"), "face 0: vertex index 0"),
            (format!("{tri}f 1 2 2\n"), "face 0 (line 4) is degenerate"),
            (format!("{tri}v 2 0 0\nf 1 2 4\n"), "face 0 (line 5) is degenerate: its vertices 1, 2 and 4"),
            (format!("{tri}v nan 0 0\nf 1 2 4\n"), "face 0 uses vertex 4, which has a non-finite"),
            (format!("{tri}v inf 0 0\nf 4 2 3\n"), "non-finite coordinate"),
            (tri.to_string(), "no triangles"),
            (format!("{tri}f 1 2\n"), "fewer than three"),
            (format!("{tri}vn 0 nan 1\nf 1//1 2//1 3//1\n"), "normal 1 is not finite"),
        ] {
            let e = err(&text);
            assert!(e.starts_with("m.obj: ") && e.contains(expect), "{e}");
            assert_eq!(e.lines().count(), 1, "{e}");
        }
    }

    #[test]
    fn bad_ply_faces_are_one_line_errors_naming_the_face() {
        let ply = |verts: &str, faces: &str, nf: usize, normals: bool| {
            let props = if normals {
                "property float nx\nproperty float ny\nproperty float nz\n"
            } else {
                ""
            };
            format!(
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                 property float z\n{props}element face {nf}\nproperty list uchar int vertex_indices\n\
                 end_header\n{verts}{faces}"
            )
        };
        let ok = "0 0 0\n1 0 0\n0 1 0\n";
        for (text, expect) in [
            (ply(ok, "3 0 1 1\n", 1, false), "face 0 is degenerate"),
            (ply("0 0 0\n1 0 0\n2 0 0\n", "3 0 1 2\n", 1, false), "degenerate"),
            (ply(ok, "3 0 1 2\n3 0 1 3\n", 2, false), "face 1 uses vertex 3"),
            (ply("0 0 0\n1 0 0\n0 nan 0\n", "3 0 1 2\n", 1, false), "non-finite"),
            (ply(ok, "", 0, false), "no triangles"),
            (
                ply("0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 nan 0 1\n", "3 0 1 2\n", 1, true),
                "vertex 2 has a non-finite normal",
            ),
        ] {
            let e = match parse_triangles(text.as_bytes(), false) {
                Err(e) => IoError::new(Path::new("m.ply"), e).to_string(),
                Ok(m) => panic!("read {m:?}"),
            };
            assert!(e.starts_with("m.ply: ") && e.contains(expect), "{e}");
            assert_eq!(e.lines().count(), 1, "{e}");
        }
        let m = parse_triangles(
            ply("0 0 0 0 0 1\n1 0 0 0 0 3\n0 1 0 0 0 0\n", "3 0 1 2\n", 1, true).as_bytes(),
            false,
        )
        .unwrap();
        assert_eq!(m.normals, Some(vec![[Vec3::ZERO; 3]]), "a zero normal: the face's");
    }
}
