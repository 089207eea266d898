//! Plain text points: one `x y z [nx ny nz]` per line, separated by spaces,
//! tabs or commas; `#` starts a comment.

use super::{IoErrorKind, PointCloud, cloud_from_world};
use glam::DVec3;

/// The fields of one line.
pub(crate) fn split_fields(line: &str) -> impl Iterator<Item = &str> {
    line.split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty())
}

/// Read an XYZ cloud (coordinates parsed as f64); the first data line fixes
/// whether normals are present (3 or 6 columns); any other line shape is an
/// error naming the line.
pub(crate) fn read_cloud(bytes: &[u8]) -> Result<PointCloud, IoErrorKind> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| IoErrorKind::Data(format!("not UTF-8 text: {e}")))?;
    let mut world = Vec::with_capacity(bytes.len() / 24);
    let mut normals = Vec::new();
    let mut cols = 0usize;
    for (ln, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let mut vals = [0f64; 6];
        let mut n = 0usize;
        for tok in split_fields(line) {
            if n == 6 {
                n += 1;
                break;
            }
            vals[n] = tok.parse::<f64>().map_err(|_| {
                IoErrorKind::Data(format!("line {}: \"{tok}\" is not a number", ln + 1))
            })?;
            n += 1;
        }
        if cols == 0 {
            if n != 3 && n != 6 {
                return Err(IoErrorKind::Data(format!(
                    "line {}: expected 3 (x y z) or 6 (x y z nx ny nz) numbers, found {n}",
                    ln + 1
                )));
            }
            cols = n;
        } else if n != cols {
            return Err(IoErrorKind::Data(format!(
                "line {}: expected {cols} numbers like the first line, found {}",
                ln + 1,
                if n > 6 {
                    "more than 6".to_string()
                } else {
                    n.to_string()
                }
            )));
        }
        world.push(DVec3::new(vals[0], vals[1], vals[2]));
        if cols == 6 {
            normals.push(DVec3::new(vals[3], vals[4], vals[5]).as_vec3());
        }
    }
    cloud_from_world(world, (cols == 6).then_some(normals), None)
}
