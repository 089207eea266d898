//! The window of candidate hits every backend fills (§4.3).

/// One ray–splat hit: the small record of pbrt's two-phase intersection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// Index of the primitive (the splat) in the slice the backend was built from.
    pub id: u32,
    /// Ray parameter of the hit.
    pub t: f32,
    /// Local coordinate along `u_axis`, divided by `r_u`.
    pub u: f32,
    /// Local coordinate along `v_axis`, divided by `r_v`.
    pub v: f32,
}

impl Candidate {
    /// `|(u, v)|`: 0 at the centre, 1 on the rim (the weight of eq. 5 is one
    /// minus this).
    #[must_use]
    pub fn radial(&self) -> f32 {
        (self.u * self.u + self.v * self.v).sqrt()
    }
}

/// How many candidates a window keeps. Beyond it the farthest (by `(t, id)`)
/// are dropped and [`CandidateHits::overflowed`] is set.
pub const MAX_CANDIDATES: usize = 32;

/// The candidate hits of one ray: the nearest at `t0`, and every other hit
/// with `t` in `[t0, t0 + xi]` (§4.3), kept sorted by `(t, id)` without
/// duplicate ids. The final set does not depend on the order in which hits
/// are offered, so any two backends that find the same hits produce the
/// same candidates.
#[derive(Clone, Debug)]
pub struct CandidateHits {
    xi: f32,
    len: usize,
    /// Smallest `t` of a hit dropped for lack of room (`+inf` when none):
    /// the window overflowed iff that hit still lies inside the final window.
    min_dropped: f32,
    items: [Candidate; MAX_CANDIDATES],
}

impl CandidateHits {
    /// An empty window of width `xi` (scene-relative, see
    /// `crate::scene::SceneScale`).
    #[must_use]
    pub fn new(xi: f32) -> CandidateHits {
        CandidateHits {
            xi,
            len: 0,
            min_dropped: f32::INFINITY,
            items: [Candidate {
                id: 0,
                t: 0.0,
                u: 0.0,
                v: 0.0,
            }; MAX_CANDIDATES],
        }
    }

    /// Empties the window, keeping `xi`.
    pub fn clear(&mut self) {
        self.len = 0;
        self.min_dropped = f32::INFINITY;
    }

    /// The window width `xi`.
    #[must_use]
    pub fn xi(&self) -> f32 {
        self.xi
    }

    /// The candidates, nearest first.
    #[must_use]
    pub fn as_slice(&self) -> &[Candidate] {
        &self.items[..self.len]
    }

    /// The nearest candidate, if any.
    #[must_use]
    pub fn nearest(&self) -> Option<&Candidate> {
        self.as_slice().first()
    }

    /// True when no hit was recorded.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// True when more than `MAX_CANDIDATES` hits fell in the final window.
    ///
    /// Like the candidates themselves this does not depend on the order in
    /// which hits were offered: a hit dropped while the window was full only
    /// counts if it still lies within `t0 + xi` of the final nearest hit.
    #[must_use]
    pub fn overflowed(&self) -> bool {
        self.len > 0 && self.min_dropped <= self.far()
    }

    /// The far end of the window, `t0 + xi`, or `+inf` while empty: a hit
    /// beyond it can never be a candidate, so traversal may stop there.
    #[must_use]
    pub fn far(&self) -> f32 {
        if self.len == 0 {
            f32::INFINITY
        } else {
            self.items[0].t + self.xi
        }
    }

    /// Offers every candidate of `other` (another structure's window of the
    /// same ray, its ids shifted by `id_offset`) and its dropped hits'
    /// record: the window both would have made together (issue 57).
    pub fn merge(&mut self, other: &CandidateHits, id_offset: u32) {
        for c in other.as_slice() {
            self.offer(Candidate {
                id: c.id + id_offset,
                ..*c
            });
        }
        self.min_dropped = self.min_dropped.min(other.min_dropped);
    }

    /// Offers a hit. Returns the (possibly shrunk) far end of the window.
    ///
    /// One pass over the kept candidates (a window holds about four) finds
    /// a duplicate id and the insertion point, the count of candidates
    /// before `c` by `(t, id)`; the later ones move up one slot each, from
    /// the last. A new nearest drops, from the end, the candidates beyond
    /// its window.
    ///
    /// A window of fewer than [`SHORT`] candidates (a camera ray's usual
    /// four to six) takes [`CandidateHits::offer_short`] instead: the same
    /// window, without the branches whose trip counts change from offer
    /// to offer.
    #[inline]
    pub fn offer(&mut self, c: Candidate) -> f32 {
        if c.t.is_nan() || c.t > self.far() {
            return self.far();
        }
        if self.len < SHORT {
            return self.offer_short(c);
        }
        let mut pos = 0;
        for h in &self.items[..self.len] {
            if h.id == c.id {
                return self.far();
            }
            // `(h.t, h.id) < (c.t, c.id)`: no kept `t` is NaN.
            pos += usize::from(h.t < c.t || (h.t == c.t && h.id < c.id));
        }
        if self.len == MAX_CANDIDATES {
            if pos == MAX_CANDIDATES {
                self.min_dropped = self.min_dropped.min(c.t);
                return self.far();
            }
            self.min_dropped = self.min_dropped.min(self.items[MAX_CANDIDATES - 1].t);
            self.len -= 1;
        }
        let mut i = self.len;
        while i > pos {
            self.items[i] = self.items[i - 1];
            i -= 1;
        }
        self.items[pos] = c;
        self.len += 1;
        if pos == 0 {
            // Sorted by `t`: the candidates within the new window (`t <=
            // far`) are a prefix, none when `far` is NaN.
            let far = self.far();
            while self.len > 0 && (far.is_nan() || self.items[self.len - 1].t > far) {
                self.len -= 1;
            }
        }
        self.far()
    }

    /// [`CandidateHits::offer`] of `c` (not NaN, not beyond the far end)
    /// into a window of fewer than [`SHORT`] candidates, on the first
    /// [`SHORT`] slots at fixed trip counts: the duplicate test and the
    /// insertion point over every slot (those past `len` masked), each
    /// slot then taking its own candidate, `c` or its predecessor's by
    /// selection, and the window's length the count of candidates within
    /// the (new) far end. That count is the loop's: the candidates are
    /// sorted by `t`, so those beyond `far` are a suffix, and when `c` is
    /// not the new nearest `far` is unchanged and every candidate, `c`
    /// too, lies within it (none when `far` is NaN, as the loop drops
    /// all). Camera rays that hit offer about six candidates each, and
    /// the loops' exits were about two mispredicted branches an offer
    /// (issue 55, twenty-fifth session).
    #[inline]
    fn offer_short(&mut self, c: Candidate) -> f32 {
        debug_assert!(self.len < SHORT && !c.t.is_nan() && !(c.t > self.far()));
        let old: [Candidate; SHORT] = std::array::from_fn(|i| self.items[i]);
        let mut dup = false;
        let mut pos = 0;
        for (i, h) in old.iter().enumerate() {
            let live = i < self.len;
            dup |= live & (h.id == c.id);
            pos += usize::from(live & (h.t < c.t || (h.t == c.t && h.id < c.id)));
        }
        if dup {
            return self.far();
        }
        for i in 0..SHORT {
            let before = old[i.saturating_sub(1)];
            self.items[i] = if i < pos {
                old[i]
            } else if i == pos {
                c
            } else {
                before
            };
        }
        let far = self.items[0].t + self.xi;
        let mut len = 0;
        for (i, h) in self.items[..SHORT].iter().enumerate() {
            len += usize::from((i <= self.len) & (h.t <= far));
        }
        self.len = len;
        self.far()
    }
}

/// Windows shorter than this take [`CandidateHits::offer_short`].
const SHORT: usize = 8;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// `offer` as it was before the short windows' path (issue 55,
    /// twenty-fifth session): the loops, for every length.
    fn offer_loops(w: &mut CandidateHits, c: Candidate) {
        if c.t.is_nan() || c.t > w.far() {
            return;
        }
        let mut pos = 0;
        for h in &w.items[..w.len] {
            if h.id == c.id {
                return;
            }
            pos += usize::from(h.t < c.t || (h.t == c.t && h.id < c.id));
        }
        if w.len == MAX_CANDIDATES {
            if pos == MAX_CANDIDATES {
                w.min_dropped = w.min_dropped.min(c.t);
                return;
            }
            w.min_dropped = w.min_dropped.min(w.items[MAX_CANDIDATES - 1].t);
            w.len -= 1;
        }
        w.items.copy_within(pos..w.len, pos + 1);
        w.items[pos] = c;
        w.len += 1;
        if pos == 0 {
            let far = w.far();
            while w.len > 0 && (far.is_nan() || w.items[w.len - 1].t > far) {
                w.len -= 1;
            }
        }
    }

    #[test]
    fn short_windows_offer_as_the_loops_do() {
        let mut rng = SplitMix64::new(55);
        let mut short_offers = 0;
        for round in 0..20_000 {
            // Widths from none to everything; t on a coarse grid (ties),
            // ids from a few (duplicates), now and then NaN or infinite.
            let xi = [0.0, 0.05, 0.2, 1.0, f32::INFINITY, f32::NAN][round % 6];
            let (mut a, mut b) = (CandidateHits::new(xi), CandidateHits::new(xi));
            let ids = 1 + rng.below(40) as u32;
            for _ in 0..rng.below(48) {
                let t = match rng.below(50) {
                    0 => f32::NAN,
                    1 => f32::INFINITY,
                    2 => f32::NEG_INFINITY,
                    _ => (rng.below(64) as f32) * 0.03125,
                };
                let c = Candidate {
                    id: rng.below(ids as usize) as u32,
                    t,
                    u: rng.next_f32(),
                    v: rng.next_f32(),
                };
                short_offers += usize::from(a.len < SHORT);
                let far = a.offer(c);
                offer_loops(&mut b, c);
                assert_eq!(a.as_slice(), b.as_slice(), "{c:?}");
                assert_eq!(far.to_bits(), b.far().to_bits());
                assert_eq!(a.min_dropped.to_bits(), b.min_dropped.to_bits());
            }
        }
        assert!(short_offers > 100_000, "{short_offers}");
    }
}
