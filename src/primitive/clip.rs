//! Clip lines (re-exported as `splat::clip`): where a splat stops at a sharp feature (a crease or a
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

    /// The same lines, in the normalised coordinates of the same splat
    /// with its radii changed from `old` to `new` (`(r_u, r_v)`, the centre
    /// kept): [`Clip::reframed`] with no shift and the radii's ratios.
    #[must_use]
    pub fn rescaled(&self, old: [f32; 2], new: [f32; 2]) -> Clip {
        self.reframed([0.0, 0.0], [new[0] / old[0], new[1] / old[1]])
    }

    /// The same lines, in the normalised coordinates of the splat moved and
    /// resized within its plane so that the old coordinates of a point are
    /// `shift + scale * (u', v')` in the new ones (e.g. freespace shrinking
    /// a splat away from a line of sight, which reframes its normal field
    /// of eq. (4) the same way): the lines stay where they are on the
    /// surface. `a u + b v <= d` becomes `(a s_u) u' + (b s_v) v' <= d - a
    /// t_u - b t_v`, renormalised to a unit `(a, b)`. A line the change
    /// would make degenerate (a zero or non-finite scale) is kept as it
    /// was.
    #[must_use]
    pub fn reframed(&self, shift: [f32; 2], scale: [f32; 2]) -> Clip {
        let mut out = *self;
        for line in &mut out.lines[..usize::from(self.count)] {
            let a = line.a * scale[0];
            let b = line.b * scale[1];
            let d = line.d - line.a * shift[0] - line.b * shift[1];
            let len = a.hypot(b);
            if len > 0.0 && len.is_finite() && d.is_finite() {
                *line = ClipLine {
                    a: a / len,
                    b: b / len,
                    d: d / len,
                };
            }
        }
        out
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

    #[test]
    fn rescaling_keeps_the_line_on_the_surface() {
        // The line x = 0.25 (physical) on a splat of radii (1, 2): u = 0.25.
        // Radii halved to (0.5, 1): the same place is u = 0.5.
        let edge = Clip::one(ClipLine {
            a: 1.0,
            b: 0.0,
            d: 0.25,
        });
        let half = edge.rescaled([1.0, 2.0], [0.5, 1.0]);
        assert_eq!(
            half.lines()[0],
            ClipLine {
                a: 1.0,
                b: 0.0,
                d: 0.5
            }
        );
        // A diagonal line on an ellipse: a physical point on it stays on it.
        let s = std::f32::consts::FRAC_1_SQRT_2;
        let diag = Clip::one(ClipLine { a: s, b: s, d: 0.1 });
        let (old, new) = ([1.0, 0.5], [0.7, 0.45]);
        let moved = diag.rescaled(old, new);
        // Physical point (x, y) on the old line: u = x, v = y / 0.5.
        let (u, v) = (0.3, (0.1 / s - 0.3) * 1.0);
        let (x, y) = (u * old[0], v * old[1]);
        let l = moved.lines()[0];
        let (u2, v2) = (x / new[0], y / new[1]);
        assert!((l.a * u2 + l.b * v2 - l.d).abs() < 1e-6);
        assert!((l.a.hypot(l.b) - 1.0).abs() < 1e-6);
        assert_eq!(Clip::NONE.rescaled(old, new), Clip::NONE);
        // Moved and shrunk (as freespace does): old (u, v) = shift + 0.6 (u', v').
        let (shift, k) = ([-0.3f32, 0.1f32], 0.6f32);
        let moved = diag.reframed(shift, [k, k]).lines()[0];
        for (u2, v2) in [(0.2f32, -0.4f32), (-0.5, 0.5), (0.9, 0.1)] {
            let (u, v) = (shift[0] + k * u2, shift[1] + k * v2);
            let before = diag.lines()[0];
            let old_side = before.a * u + before.b * v - before.d;
            let new_side = moved.a * u2 + moved.b * v2 - moved.d;
            assert!(
                (old_side - new_side * k).abs() < 1e-6,
                "{old_side} {new_side}"
            );
        }
    }
}
