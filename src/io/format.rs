//! The point formats as one table: each format's name, extensions and
//! first bytes, its whole-file reader and, where it can, its streamer.
//! Reading ([`super::read_points`], [`super::parse_points`]) and
//! streaming ([`super::stream_points`]) dispatch here, once, by format.

use super::batch::{PointBatch, StreamInfo};
use super::{IoErrorKind, PointCloud};
use super::{e57file, las, pcd, ply, xyz};
use std::path::Path;

/// The point file formats understood by [`super::read_points`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Stanford PLY (ascii, binary little or big endian).
    Ply,
    /// PCL's PCD v0.7 (ascii, binary, binary_compressed).
    Pcd,
    /// Whitespace separated `x y z [nx ny nz]` text.
    Xyz,
    /// ASPRS LAS, or LAZ (LASzip-compressed LAS).
    Las,
    /// ASTM E57: several scans, each placed by its pose.
    E57,
}

impl Format {
    /// The format from the file extension (`.ply`, `.pcd`, `.xyz`, `.txt`,
    /// `.las`, `.laz`, `.e57`, case-insensitive), or `None`.
    #[must_use]
    pub fn from_extension(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "ply" => Some(Format::Ply),
            "pcd" => Some(Format::Pcd),
            "xyz" | "txt" => Some(Format::Xyz),
            "las" | "laz" => Some(Format::Las),
            "e57" => Some(Format::E57),
            _ => None,
        }
    }

    /// The format guessed from a file's first bytes, or `None`.
    #[must_use]
    pub fn sniff(head: &[u8]) -> Option<Format> {
        if head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n") {
            return Some(Format::Ply);
        }
        if head.starts_with(b"LASF") {
            return Some(Format::Las);
        }
        if head.starts_with(super::e57file::MAGIC) {
            return Some(Format::E57);
        }
        let text = String::from_utf8_lossy(head);
        let first = text
            .lines()
            .map(str::trim)
            .find(|l| !l.is_empty() && (!l.starts_with('#') || l.contains(".PCD")));
        match first {
            Some(l)
                if l.contains(".PCD") || l.starts_with("VERSION") || l.starts_with("FIELDS") =>
            {
                Some(Format::Pcd)
            }
            Some(l) => {
                let n = super::xyz::split_fields(l).count();
                let numeric = super::xyz::split_fields(l).all(|t| t.parse::<f64>().is_ok());
                (numeric && (n == 3 || n == 6)).then_some(Format::Xyz)
            }
            None => None,
        }
    }
}

impl Format {
    /// Every format, as `--format` lists them.
    pub const ALL: [Format; 5] = [
        Format::Ply,
        Format::Pcd,
        Format::Xyz,
        Format::Las,
        Format::E57,
    ];

    /// The name `--format` takes (the usual extension).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Format::Ply => "ply",
            Format::Pcd => "pcd",
            Format::Xyz => "xyz",
            Format::Las => "las",
            Format::E57 => "e57",
        }
    }

    /// The format a name or extension stands for (`ply`, `pcd`, `xyz`,
    /// `txt`, `las`, `laz`, `e57`; case-insensitive), or `None`.
    #[must_use]
    pub fn parse(name: &str) -> Option<Format> {
        Format::from_extension(Path::new(&format!("x.{}", name.trim())))
    }

    /// The format of a file: by its extension, else by its first bytes
    /// `head`.
    #[must_use]
    pub fn detect(path: &Path, head: &[u8]) -> Option<Format> {
        Format::from_extension(path).or_else(|| Format::sniff(&head[..head.len().min(4096)]))
    }

    /// The whole-file reader of this format, on the file's bytes.
    pub(crate) fn read_cloud(self, bytes: &[u8]) -> Result<PointCloud, IoErrorKind> {
        match self {
            Format::Ply => ply::read_cloud(bytes),
            Format::Pcd => pcd::read_cloud(bytes),
            Format::Xyz => xyz::read_cloud(bytes),
            Format::Las => las::read_cloud(bytes),
            Format::E57 => e57file::read_cloud(bytes),
        }
    }

    /// This format's streamer on the file at `path`, where it has one and
    /// the file suits it (a PLY streams when it is binary little-endian
    /// with scalar vertex properties first); `Ok(None)`: read the file
    /// whole instead.
    pub(crate) fn stream(
        self,
        path: &Path,
        each: &mut dyn FnMut(&PointBatch<'_>) -> Result<(), String>,
    ) -> Result<Option<StreamInfo>, IoErrorKind> {
        match self {
            Format::Ply => match ply::binary_ply_layout(path)? {
                Some(layout) => ply::stream_binary_ply(path, &layout, each).map(Some),
                None => Ok(None),
            },
            Format::Las => las::stream(path, each).map(Some),
            Format::E57 => e57file::stream(path, each).map(Some),
            Format::Pcd | Format::Xyz => Ok(None),
        }
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
