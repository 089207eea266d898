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
    /// its window. Inlined into the leaves' loops (issue 55, twenty-fifth
    /// session: a call a candidate, about six a camera ray that hits).
    #[inline(always)]
    pub fn offer(&mut self, c: Candidate) -> f32 {
        if c.t.is_nan() || c.t > self.far() {
            return self.far();
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
}
