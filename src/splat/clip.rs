//! Clip lines: where a splat stops at a sharp feature (a crease or a
//! corner), the part of its disc beyond a line in its own plane is not
//! surface.
//!
//! A line is kept in the splat-local coordinates normalised by the radii,
//! the same `(u, v)` the intersection yields and the Phong field of eq. (4)
//! reads (`u² + v² <= 1` on the disc), so it is scale-free like the field:
//! the unit frame's splats keep their lines when scaled back. A splat keeps
//! the points of its disc with `a u + b v <= d` for every line it carries.

/// One clip line `a u + b v = d` in normalised splat coordinates; the splat
/// keeps the side `a u + b v <= d`. `(a, b)` is a unit vector pointing away
/// from the kept part; `d` is the line's signed distance from the centre
/// (in units of the radii), `-1 < d < 1` for a line that crosses the disc.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct ClipLine {
    /// Outward normal of the line, `u` component.
    pub a: f32,
    /// Outward normal of the line, `v` component.
    pub b: f32,
    /// Signed offset of the line from the splat centre.
    pub d: f32,
}

impl ClipLine {
    /// Whether the point `(u, v)` lies on the kept side (the line itself
    /// counts as kept, as the rim does for the disc).
    #[inline]
    #[must_use]
    pub fn keeps(&self, u: f32, v: f32) -> bool {
        self.a * u + self.b * v <= self.d
    }
}

/// The clip lines of one splat: none (a whole disc), one (an edge) or two
/// (a corner).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Clip {
    lines: [ClipLine; 2],
    count: u8,
}

impl Clip {
    /// No clip line: the whole disc is surface.
    pub const NONE: Clip = Clip {
        lines: [ClipLine {
            a: 0.0,
            b: 0.0,
            d: 0.0,
        }; 2],
        count: 0,
    };

    /// One clip line (a splat on an edge).
    #[must_use]
    pub fn one(line: ClipLine) -> Clip {
        Clip {
            lines: [line, ClipLine::default()],
            count: 1,
        }
    }

    /// Two clip lines (a splat at a corner).
    #[must_use]
    pub fn two(first: ClipLine, second: ClipLine) -> Clip {
        Clip {
            lines: [first, second],
            count: 2,
        }
    }

    /// The lines this splat carries (0, 1 or 2).
    #[must_use]
    pub fn lines(&self) -> &[ClipLine] {
        &self.lines[..usize::from(self.count)]
    }

    /// Whether the splat carries no clip line.
    #[must_use]
    pub fn is_none(&self) -> bool {
        self.count == 0
    }

    /// Whether `(u, v)` (normalised splat coordinates) is kept by every line.
    #[inline]
    #[must_use]
    pub fn keeps(&self, u: f32, v: f32) -> bool {
        self.lines().iter().all(|l| l.keeps(u, v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn none_keeps_everything_and_lines_cut() {
        assert!(Clip::NONE.keeps(0.9, -0.9));
        let edge = Clip::one(ClipLine {
            a: 1.0,
            b: 0.0,
            d: 0.25,
        });
        assert!(edge.keeps(0.25, 0.0));
        assert!(!edge.keeps(0.26, 0.0));
        let corner = Clip::two(
            ClipLine {
                a: 1.0,
                b: 0.0,
                d: 0.0,
            },
            ClipLine {
                a: 0.0,
                b: 1.0,
                d: 0.0,
            },
        );
        assert_eq!(corner.lines().len(), 2);
        assert!(corner.keeps(-0.5, -0.5));
        assert!(!corner.keeps(-0.5, 0.1));
        assert!(!corner.keeps(0.1, -0.5));
    }
}
