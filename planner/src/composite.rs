//! Composite paths: a program of consecutive lines and arcs traversed in one motion, without
//! stopping where the tangent is continuous.
//!
//! Geometry ([`CompositePath`]): up to [`MAX_SEGMENTS`] segments joined end to start, parametrised
//! by the total length `s` in the combined metric of [`crate::path`]
//! (`ds^2 = dx^2 + dy^2 + (R dphi)^2`, `R` the rotation radius in mm/rad). A junction is *smooth*
//! (G1) when the unit tangents of the two segments (in that metric) differ by at most
//! [`G1_TOLERANCE_RAD`]; otherwise it is a corner. [`CompositePath::blend_corners`] replaces a
//! corner between two lines by a tangent arc of a given radius (shrunk if the lines are too
//! short), which makes the junction smooth.
//!
//! Speed ([`CompositeMotion::plan`]), the usual look-ahead scheme of CNC and robot planners:
//!
//! 1. a speed limit per segment: the program speed, the segment's own speed, and on arcs the
//!    centripetal limit `v_xy <= sqrt(amax * r)` (converted to the combined metric);
//! 2. junction limits: a corner must be passed at rest; a smooth junction at most at the smaller
//!    limit of its two segments. Consecutive segments with smooth junctions and the same limit are
//!    merged into one *section*;
//! 3. a backward and a forward pass over the section boundaries lower each boundary speed until
//!    every section can change from its start to its end speed within its length with the
//!    jerk-limited acceleration (zero acceleration at the boundaries);
//! 4. every section gets the profiler's time-optimal one-DoF profile (position interface) from
//!    (0, v_start, 0) to (length, v_end, 0) with the section's speed limit, `amax` and `jmax`.
//!
//! The result is continuous in position, speed and acceleration along the whole composite,
//! respects the speed, acceleration and jerk limits along the path, and stops exactly at the end.
//! Everything is fixed-size: planning and sampling never allocate.

use crate::path::{Pose, Primitive, DEFAULT_ROTATION_RADIUS_MM};
use crate::profiler::{step1::Step1, ControlInterface, Limits, State};

/// Maximal number of segments of a composite path (after corner blending).
pub const MAX_SEGMENTS: usize = 64;

/// Largest angle between the tangents of two segments (rad, combined metric) for which their
/// junction counts as smooth and may be passed without slowing down. A junction passed at speed
/// `v` with this angle has a velocity jump of at most `v * 1e-3`.
pub const G1_TOLERANCE_RAD: f64 = 1e-3;

/// Shortest segment accepted, mm (combined metric).
pub const MIN_SEGMENT_LENGTH_MM: f64 = 1e-9;

/// Maximal number of constant-jerk phases of one section's profile.
const MAX_PHASES: usize = 8;

/// Invalid composite path or limits, or a failed plan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CompositeError {
    /// A number is NaN or infinite.
    #[error("composite parameter {0} is not finite")]
    NotFinite(&'static str),
    /// A radius, length or limit is not strictly positive.
    #[error("composite parameter {0} must be > 0 (got {1})")]
    NotPositive(&'static str, f64),
    /// A blend radius is negative or not finite.
    #[error("blend radius must be a finite number >= 0 (got {0})")]
    BadBlendRadius(f64),
    /// More than [`MAX_SEGMENTS`] segments.
    #[error("a composite path holds at most {MAX_SEGMENTS} segments")]
    TooManySegments,
    /// A segment has (almost) no length.
    #[error("segment {segment} has no length (it ends where it starts)")]
    ZeroLength {
        /// 0-based index of the segment in the order it was added.
        segment: usize,
    },
    /// An arc's centre is (almost) at its start point.
    #[error("segment {segment}: the arc's centre is at its start point (radius 0)")]
    ZeroRadius {
        /// 0-based index of the segment in the order it was added.
        segment: usize,
    },
    /// The path has no segment.
    #[error("a composite path needs at least one segment")]
    Empty,
    /// Too few or too many polyline vertices.
    #[error("a polyline needs 2 ..= {max} vertices (got {0})", max = MAX_SEGMENTS + 1)]
    Vertices(usize),
    /// The profiler found no profile for a section (numerical failure).
    #[error("no speed profile found for the section starting at segment {segment}")]
    NoProfile {
        /// First segment of the section.
        segment: usize,
    },
}

/// Where a segment comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentSource {
    /// The `k`-th segment added by the caller (0-based), possibly shortened by blending.
    Primitive(usize),
    /// The arc blending the corner between primitives `k` and `k + 1`.
    Blend(usize),
}

/// Geometry of one segment (mm, rad): a line or an arc, as in [`crate::path`].
pub type SegmentGeometry = Primitive;

/// One segment of a composite path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    geo: SegmentGeometry,
    len: f64,
    rot: f64,
    speed: f64,
    source: SegmentSource,
}

impl Segment {
    fn new(geo: SegmentGeometry, rot: f64, speed: f64, source: SegmentSource) -> Segment {
        let len = geo.length(rot);
        Segment {
            geo,
            len,
            rot,
            speed,
            source,
        }
    }

    /// The geometry.
    pub fn geometry(&self) -> &SegmentGeometry {
        &self.geo
    }

    /// Length in the combined metric, mm.
    pub fn length(&self) -> f64 {
        self.len
    }

    /// The segment's own speed limit, mm/s (infinite if none).
    pub fn speed_limit(&self) -> f64 {
        self.speed
    }

    /// Where the segment comes from.
    pub fn source(&self) -> SegmentSource {
        self.source
    }

    /// Radius of an arc in mm (None for a line).
    pub fn radius(&self) -> Option<f64> {
        match self.geo {
            SegmentGeometry::Arc { r, .. } => Some(r),
            SegmentGeometry::Line { .. } => None,
        }
    }

    /// Fraction of the combined length that is travelled in the plane (`|d(x, y)| / ds`, in
    /// [0, 1]; constant along a segment).
    pub fn planar_fraction(&self) -> f64 {
        if self.len <= 0.0 {
            return 0.0;
        }
        let xy = match self.geo {
            SegmentGeometry::Line { a, b } => (b.x - a.x).hypot(b.y - a.y),
            SegmentGeometry::Arc { r, sweep, .. } => (r * sweep).abs(),
        };
        (xy / self.len).min(1.0)
    }

    /// Pose and d(pose)/ds (1/1, 1/1, rad/mm) at length `s` mm from the segment start (clamped).
    pub fn sample(&self, s: f64) -> (Pose, Pose) {
        self.geo.sample(self.len, s)
    }

    /// Start pose.
    pub fn start(&self) -> Pose {
        self.sample(0.0).0
    }

    /// End pose.
    pub fn end(&self) -> Pose {
        self.sample(self.len).0
    }

    /// Unit tangent (dx/ds, dy/ds, R dphi/ds) at length `s`.
    fn tangent(&self, s: f64) -> [f64; 3] {
        let d = self.sample(s).1;
        [d.x, d.y, self.rot * d.phi]
    }
}

fn finite(name: &'static str, v: f64) -> Result<f64, CompositeError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(CompositeError::NotFinite(name))
    }
}

fn finite_pose(p: &Pose) -> Result<(), CompositeError> {
    finite("x", p.x)?;
    finite("y", p.y)?;
    finite("phi", p.phi)?;
    Ok(())
}

fn angle_between(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cx = a[1] * b[2] - a[2] * b[1];
    let cy = a[2] * b[0] - a[0] * b[2];
    let cz = a[0] * b[1] - a[1] * b[0];
    (cx * cx + cy * cy + cz * cz).sqrt().atan2(dot)
}

/// A sequence of lines and arcs, each starting where the previous one ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompositePath {
    segs: [Segment; MAX_SEGMENTS],
    /// Cumulative length at the start of each segment; `cum[n]` is the total length.
    cum: [f64; MAX_SEGMENTS + 1],
    n: usize,
    /// Number of primitives added (for [`SegmentSource::Primitive`]).
    added: usize,
    rot: f64,
    start: Pose,
}

impl CompositePath {
    /// An empty composite starting at `start` with the default rotation radius.
    pub fn new(start: Pose) -> Result<CompositePath, CompositeError> {
        Self::with_rotation_radius(start, DEFAULT_ROTATION_RADIUS_MM)
    }

    /// An empty composite starting at `start` with rotation radius `r` mm/rad (> 0).
    pub fn with_rotation_radius(start: Pose, r: f64) -> Result<CompositePath, CompositeError> {
        finite_pose(&start)?;
        if !(r.is_finite() && r > 0.0) {
            return Err(CompositeError::NotPositive("rotation radius", r));
        }
        let dummy = Segment::new(
            SegmentGeometry::Line { a: start, b: start },
            r,
            f64::INFINITY,
            SegmentSource::Primitive(0),
        );
        Ok(CompositePath {
            segs: [dummy; MAX_SEGMENTS],
            cum: [0.0; MAX_SEGMENTS + 1],
            n: 0,
            added: 0,
            rot: r,
            start,
        })
    }

    fn push(&mut self, seg: Segment) -> Result<(), CompositeError> {
        if self.n >= MAX_SEGMENTS {
            return Err(CompositeError::TooManySegments);
        }
        self.segs[self.n] = seg;
        self.cum[self.n + 1] = self.cum[self.n] + seg.len;
        self.n += 1;
        Ok(())
    }

    fn check_speed(speed: Option<f64>) -> Result<f64, CompositeError> {
        match speed {
            None => Ok(f64::INFINITY),
            Some(v) if v.is_finite() && v > 0.0 => Ok(v),
            Some(v) => Err(CompositeError::NotPositive("segment speed", v)),
        }
    }

    /// Appends a line from the current end to `to`, with an optional own speed limit (mm/s).
    pub fn line_to(&mut self, to: Pose, speed: Option<f64>) -> Result<(), CompositeError> {
        finite_pose(&to)?;
        let speed = Self::check_speed(speed)?;
        let k = self.added;
        let seg = Segment::new(
            SegmentGeometry::Line {
                a: self.end(),
                b: to,
            },
            self.rot,
            speed,
            SegmentSource::Primitive(k),
        );
        if seg.len < MIN_SEGMENT_LENGTH_MM {
            return Err(CompositeError::ZeroLength { segment: k });
        }
        self.push(seg)?;
        self.added += 1;
        Ok(())
    }

    /// Appends an arc around (`cx`, `cy`) mm from the current end, sweeping `sweep` rad
    /// (positive: counter-clockwise), orientation changing linearly to `phi_end` rad; optional own
    /// speed limit (mm/s). The radius is the distance of the current end from the centre.
    pub fn arc_around(
        &mut self,
        cx: f64,
        cy: f64,
        sweep: f64,
        phi_end: f64,
        speed: Option<f64>,
    ) -> Result<(), CompositeError> {
        finite("cx", cx)?;
        finite("cy", cy)?;
        finite("sweep", sweep)?;
        finite("phi", phi_end)?;
        let speed = Self::check_speed(speed)?;
        let k = self.added;
        let p = self.end();
        let r = (p.x - cx).hypot(p.y - cy);
        if r < MIN_SEGMENT_LENGTH_MM {
            return Err(CompositeError::ZeroRadius { segment: k });
        }
        let seg = Segment::new(
            SegmentGeometry::Arc {
                cx,
                cy,
                r,
                theta0: (p.y - cy).atan2(p.x - cx),
                sweep,
                phi0: p.phi,
                phi1: phi_end,
            },
            self.rot,
            speed,
            SegmentSource::Primitive(k),
        );
        if seg.len < MIN_SEGMENT_LENGTH_MM {
            return Err(CompositeError::ZeroLength { segment: k });
        }
        self.push(seg)?;
        self.added += 1;
        Ok(())
    }

    /// A polyline through `vertices` (2 ..= MAX_SEGMENTS + 1) whose interior corners are rounded
    /// by tangent arcs of `blend_radius` mm (0: sharp corners). A closed polyline (last vertex =
    /// first) keeps its start corner sharp: the motion starts and ends there at rest.
    pub fn polyline(vertices: &[Pose], blend_radius: f64) -> Result<CompositePath, CompositeError> {
        if vertices.len() < 2 || vertices.len() > MAX_SEGMENTS + 1 {
            return Err(CompositeError::Vertices(vertices.len()));
        }
        if !(blend_radius.is_finite() && blend_radius >= 0.0) {
            return Err(CompositeError::BadBlendRadius(blend_radius));
        }
        let mut c = CompositePath::new(vertices[0])?;
        for v in &vertices[1..] {
            c.line_to(*v, None)?;
        }
        c.blend_corners(|_| blend_radius)
    }

    /// A closed rectangle with centre (`center.x`, `center.y`), sides `width` (along the direction
    /// `angle` rad) and `height`, at constant orientation `center.phi`, traversed
    /// counter-clockwise from the middle of the first `width` side back to it. With
    /// `blend_radius` > 0 all four corners are rounded (G1 everywhere: the speed stays
    /// continuous around the loop); with 0 the motion stops at each corner.
    pub fn rectangle(
        center: Pose,
        width: f64,
        height: f64,
        angle: f64,
        blend_radius: f64,
    ) -> Result<CompositePath, CompositeError> {
        finite_pose(&center)?;
        finite("angle", angle)?;
        if !(width.is_finite() && width > 0.0) {
            return Err(CompositeError::NotPositive("width", width));
        }
        if !(height.is_finite() && height > 0.0) {
            return Err(CompositeError::NotPositive("height", height));
        }
        let (c, s) = (angle.cos(), angle.sin());
        let at = |u: f64, v: f64| {
            Pose::new(
                center.x + u * c - v * s,
                center.y + u * s + v * c,
                center.phi,
            )
        };
        let (w, h) = (width / 2.0, height / 2.0);
        let pts = [
            at(0.0, -h),
            at(w, -h),
            at(w, h),
            at(-w, h),
            at(-w, -h),
            at(0.0, -h),
        ];
        Self::polyline(&pts, blend_radius)
    }

    /// The same path with every corner between two lines (junction `j`, between segments `j - 1`
    /// and `j` of this path, 1-based as in [`CompositePath::junction_angle`]) rounded by a tangent
    /// arc of radius `radius(j)` mm (0: kept sharp). The arc lies in the plane; the orientation
    /// changes linearly along it between the orientations at its tangent points. If the lines are
    /// too short, the radius is reduced so that each corner uses at most half of each line.
    /// Corners involving an arc, reversals and lines without planar motion stay sharp.
    pub fn blend_corners(
        &self,
        radius: impl Fn(usize) -> f64,
    ) -> Result<CompositePath, CompositeError> {
        let mut out = CompositePath::with_rotation_radius(self.start, self.rot)?;
        out.added = self.added;
        // Trim of each line at its start and end (planar distance, mm) and the blend arcs.
        let mut trim_start = [0.0f64; MAX_SEGMENTS];
        let mut trim_end = [0.0f64; MAX_SEGMENTS];
        let mut blend: [Option<Segment>; MAX_SEGMENTS] = [None; MAX_SEGMENTS];
        for j in 1..self.n {
            let r = radius(j);
            if !(r.is_finite() && r >= 0.0) {
                return Err(CompositeError::BadBlendRadius(r));
            }
            if r == 0.0 || self.junction_angle(j) <= G1_TOLERANCE_RAD {
                continue;
            }
            let (s1, s2) = (&self.segs[j - 1], &self.segs[j]);
            let (SegmentGeometry::Line { a: a1, b: p }, SegmentGeometry::Line { a: _, b: b2 }) =
                (s1.geo, s2.geo)
            else {
                continue;
            };
            let (l1, l2) = (
                (p.x - a1.x).hypot(p.y - a1.y),
                (b2.x - p.x).hypot(b2.y - p.y),
            );
            if l1 < MIN_SEGMENT_LENGTH_MM || l2 < MIN_SEGMENT_LENGTH_MM {
                continue;
            }
            let d1 = [(p.x - a1.x) / l1, (p.y - a1.y) / l1];
            let d2 = [(b2.x - p.x) / l2, (b2.y - p.y) / l2];
            let cross = d1[0] * d2[1] - d1[1] * d2[0];
            let dot = d1[0] * d2[0] + d1[1] * d2[1];
            let theta = cross.abs().atan2(dot);
            if theta > std::f64::consts::PI - 1e-6 || theta <= G1_TOLERANCE_RAD {
                continue;
            }
            let half = (theta / 2.0).tan();
            let t = (r * half).min(0.5 * l1.min(l2));
            let r = t / half;
            if r < MIN_SEGMENT_LENGTH_MM {
                continue;
            }
            trim_end[j - 1] = t;
            trim_start[j] = t;
            let u1 = 1.0 - t / l1;
            let u2 = t / l2;
            let t1 = Pose::new(
                a1.x + (p.x - a1.x) * u1,
                a1.y + (p.y - a1.y) * u1,
                a1.phi + (p.phi - a1.phi) * u1,
            );
            let phi2 = p.phi + (b2.phi - p.phi) * u2;
            let sigma = cross.signum();
            let (cx, cy) = (t1.x - sigma * r * d1[1], t1.y + sigma * r * d1[0]);
            blend[j] = Some(Segment::new(
                SegmentGeometry::Arc {
                    cx,
                    cy,
                    r,
                    theta0: (t1.y - cy).atan2(t1.x - cx),
                    sweep: sigma * theta,
                    phi0: t1.phi,
                    phi1: phi2,
                },
                self.rot,
                s1.speed.min(s2.speed),
                SegmentSource::Blend(match s1.source {
                    SegmentSource::Primitive(k) | SegmentSource::Blend(k) => k,
                }),
            ));
        }
        for i in 0..self.n {
            if let Some(b) = blend[i] {
                out.push(b)?;
            }
            let seg = &self.segs[i];
            match seg.geo {
                SegmentGeometry::Line { a, b } if trim_start[i] > 0.0 || trim_end[i] > 0.0 => {
                    let l = (b.x - a.x).hypot(b.y - a.y);
                    let u1 = 1.0 - trim_end[i] / l;
                    let start = out.end();
                    let end = if trim_end[i] > 0.0 {
                        Pose::new(
                            a.x + (b.x - a.x) * u1,
                            a.y + (b.y - a.y) * u1,
                            a.phi + (b.phi - a.phi) * u1,
                        )
                    } else {
                        b
                    };
                    let s = Segment::new(
                        SegmentGeometry::Line { a: start, b: end },
                        self.rot,
                        seg.speed,
                        seg.source,
                    );
                    if s.len >= MIN_SEGMENT_LENGTH_MM {
                        out.push(s)?;
                    }
                }
                SegmentGeometry::Line { b, .. } => {
                    let s = Segment::new(
                        SegmentGeometry::Line { a: out.end(), b },
                        self.rot,
                        seg.speed,
                        seg.source,
                    );
                    out.push(s)?;
                }
                SegmentGeometry::Arc { .. } => out.push(*seg)?,
            }
        }
        Ok(out)
    }

    /// Rotation radius `R`, mm/rad.
    pub fn rotation_radius(&self) -> f64 {
        self.rot
    }

    /// Number of segments.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True if there is no segment.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The segments.
    pub fn segments(&self) -> &[Segment] {
        &self.segs[..self.n]
    }

    /// Length at the start of segment `i` (`i = len()` gives the total), mm.
    pub fn segment_start(&self, i: usize) -> f64 {
        self.cum[i.min(self.n)]
    }

    /// Total length in the combined metric, mm.
    pub fn length(&self) -> f64 {
        self.cum[self.n]
    }

    /// Start pose.
    pub fn start(&self) -> Pose {
        self.start
    }

    /// End pose (the start for an empty path).
    pub fn end(&self) -> Pose {
        if self.n == 0 {
            self.start
        } else {
            self.segs[self.n - 1].end()
        }
    }

    /// Angle (rad, combined metric) between the end tangent of segment `j - 1` and the start
    /// tangent of segment `j`, for junctions `j = 1 .. len()`; 0 otherwise.
    pub fn junction_angle(&self, j: usize) -> f64 {
        if j == 0 || j >= self.n {
            return 0.0;
        }
        let a = &self.segs[j - 1];
        angle_between(a.tangent(a.len), self.segs[j].tangent(0.0))
    }

    /// True if junction `j` may be passed without stopping (tangent angle within
    /// [`G1_TOLERANCE_RAD`]).
    pub fn junction_is_smooth(&self, j: usize) -> bool {
        self.junction_angle(j) <= G1_TOLERANCE_RAD
    }

    /// Index of the segment containing length `s` (a junction belongs to the later segment).
    pub fn segment_at(&self, s: f64) -> usize {
        if self.n == 0 {
            return 0;
        }
        let (mut lo, mut hi) = (0, self.n);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if self.cum[mid] <= s {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// Pose and d(pose)/ds at length `s` mm (clamped to `[0, length]`); the end pose exactly at
    /// the end.
    pub fn sample(&self, s: f64) -> (Pose, Pose) {
        if self.n == 0 {
            return (self.start, Pose::default());
        }
        let i = self.segment_at(s);
        self.segs[i].sample(s - self.cum[i])
    }
}

/// Limits of the motion along a composite path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompositeLimits {
    /// Speed along the path, mm/s (combined metric).
    pub vmax: f64,
    /// Acceleration along the path and centripetal acceleration on arcs, mm/s^2.
    pub amax: f64,
    /// Jerk along the path, mm/s^3.
    pub jmax: f64,
}

#[derive(Clone, Copy, Debug, Default)]
struct Section {
    /// First segment.
    seg0: usize,
    /// Start time, s.
    t0: f64,
    /// Start length on the path, mm.
    s0: f64,
    /// Length, mm.
    len: f64,
    /// Speed limit, mm/s.
    vmax: f64,
    /// Start and end speed, mm/s.
    v0: f64,
    v1: f64,
    duration: f64,
    start: State,
    n: usize,
    dur: [f64; MAX_PHASES],
    jerk: [f64; MAX_PHASES],
}

impl Section {
    /// (State relative to the section start, jerk) at time `t` in the section.
    fn at(&self, t: f64) -> (State, f64) {
        let mut st = self.start;
        let mut t = t.max(0.0);
        for k in 0..self.n {
            if t < self.dur[k] {
                return (st.integrate(t, self.jerk[k]), self.jerk[k]);
            }
            st = st.integrate(self.dur[k], self.jerk[k]);
            t -= self.dur[k];
        }
        (State::new(self.len, self.v1, 0.0), 0.0)
    }
}

/// One sample of a composite motion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompositeSample {
    /// Pose (mm, mm, rad).
    pub pose: Pose,
    /// Pose rate (mm/s, mm/s, rad/s).
    pub velocity: Pose,
    /// Length travelled along the path, mm.
    pub s: f64,
    /// Speed along the path, mm/s.
    pub speed: f64,
    /// Acceleration along the path, mm/s^2.
    pub acceleration: f64,
    /// Jerk along the path, mm/s^3.
    pub jerk: f64,
    /// Index of the segment the pose is on.
    pub segment: usize,
}

/// A composite path with its planned, jerk-limited speed profile (from rest to rest).
#[derive(Clone, Debug)]
pub struct CompositeMotion {
    path: CompositePath,
    limits: CompositeLimits,
    /// Speed limit per segment, mm/s.
    vlim: [f64; MAX_SEGMENTS],
    sections: [Section; MAX_SEGMENTS],
    m: usize,
    duration: f64,
}

/// Shortest length (mm) needed to change the speed from `v0` to `v1` (mm/s) with zero
/// acceleration at both ends, acceleration `amax` and jerk `jmax` (symmetric acceleration pulse,
/// so the length is the mean speed times the duration).
pub fn speed_change_length(v0: f64, v1: f64, amax: f64, jmax: f64) -> f64 {
    let dv = (v1 - v0).abs();
    let t = if dv * jmax >= amax * amax {
        dv / amax + amax / jmax
    } else {
        2.0 * (dv / jmax).sqrt()
    };
    0.5 * (v0 + v1) * t
}

/// Largest speed `<= cap` reachable from (or brakeable to) speed `v` within `len` mm.
fn reachable(v: f64, len: f64, cap: f64, amax: f64, jmax: f64) -> f64 {
    // A relative margin keeps every section strictly feasible for the profiler.
    let len = len * (1.0 - 1e-9);
    if cap <= v || speed_change_length(v, cap, amax, jmax) <= len {
        return cap.max(0.0);
    }
    let (mut lo, mut hi) = (v, cap);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if speed_change_length(v, mid, amax, jmax) <= len {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-13 * hi.max(1.0) {
            break;
        }
    }
    lo
}

impl CompositeMotion {
    /// Plans the speed profile along `path` from rest to rest (see the module documentation).
    pub fn plan(
        path: &CompositePath,
        limits: &CompositeLimits,
    ) -> Result<CompositeMotion, CompositeError> {
        for (n, v) in [
            ("vmax", limits.vmax),
            ("amax", limits.amax),
            ("jmax", limits.jmax),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(CompositeError::NotPositive(n, v));
            }
        }
        if path.is_empty() {
            return Err(CompositeError::Empty);
        }
        let (amax, jmax) = (limits.amax, limits.jmax);
        let n = path.n;
        let mut vlim = [0.0f64; MAX_SEGMENTS];
        for (i, seg) in path.segments().iter().enumerate() {
            let mut v = limits.vmax.min(seg.speed);
            if let Some(r) = seg.radius() {
                let k = seg.planar_fraction();
                if k > 0.0 {
                    // Centripetal acceleration (v k)^2 / r <= amax.
                    v = v.min((amax * r).sqrt() / k);
                }
            }
            vlim[i] = v;
        }
        // Sections: merge segments joined smoothly with the same speed limit.
        let mut sections = [Section::default(); MAX_SEGMENTS];
        // Boundary caps: bcap[k] is the cap at the start of section k; bcap[m] = 0.
        let mut bcap = [0.0f64; MAX_SEGMENTS + 1];
        let mut m = 0;
        for i in 0..n {
            let smooth = i > 0 && path.junction_is_smooth(i);
            let same = i > 0 && (vlim[i] - vlim[i - 1]).abs() <= 1e-12 * vlim[i];
            if i > 0 && smooth && same {
                sections[m - 1].len += path.segs[i].len;
                continue;
            }
            bcap[m] = if i == 0 || !smooth {
                0.0
            } else {
                vlim[i].min(vlim[i - 1])
            };
            sections[m] = Section {
                seg0: i,
                s0: path.cum[i],
                len: path.segs[i].len,
                vmax: vlim[i],
                ..Section::default()
            };
            m += 1;
        }
        bcap[m] = 0.0;
        // Backward then forward pass.
        let mut vb = bcap;
        for k in (1..m).rev() {
            vb[k] = reachable(vb[k + 1], sections[k].len, vb[k], amax, jmax);
        }
        for k in 1..m {
            vb[k] = reachable(vb[k - 1], sections[k - 1].len, vb[k], amax, jmax);
        }
        let mut t0 = 0.0;
        for k in 0..m {
            let sec = &mut sections[k];
            sec.v0 = vb[k];
            sec.v1 = vb[k + 1];
            sec.t0 = t0;
            let lim = Limits::symmetric(sec.vmax, amax, jmax);
            let err = CompositeError::NoProfile { segment: sec.seg0 };
            let step = Step1::solve(
                ControlInterface::Position,
                &State::new(0.0, sec.v0, 0.0),
                &State::new(sec.len, sec.v1, 0.0),
                &lim,
            )
            .ok_or(err.clone())?;
            let p = step.optimal_profile();
            if p.len() > MAX_PHASES {
                return Err(err);
            }
            sec.start = p.start();
            sec.n = p.len();
            for i in 0..p.len() {
                (sec.dur[i], sec.jerk[i]) = p.segment(i);
            }
            sec.duration = p.duration();
            t0 += sec.duration;
        }
        Ok(CompositeMotion {
            path: *path,
            limits: *limits,
            vlim,
            sections,
            m,
            duration: t0,
        })
    }

    /// The path.
    pub fn path(&self) -> &CompositePath {
        &self.path
    }

    /// The limits it was planned with.
    pub fn limits(&self) -> &CompositeLimits {
        &self.limits
    }

    /// Duration in s.
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// Speed limit of segment `i` (program speed, own speed, centripetal limit), mm/s.
    pub fn segment_speed_limit(&self, i: usize) -> f64 {
        self.vlim[i.min(MAX_SEGMENTS - 1)]
    }

    /// Number of sections (runs of smoothly joined segments with the same speed limit, each
    /// planned with one profile).
    pub fn sections(&self) -> usize {
        self.m
    }

    /// Planned speed (mm/s) at the start of segment `i` (0 at the start, at corners and at
    /// `i = len()`, the end). Inside a section the speed is sampled from its profile.
    pub fn speed_at_segment_start(&self, i: usize) -> f64 {
        if i >= self.path.n {
            return 0.0;
        }
        self.sample(self.time_at_length(self.path.cum[i])).speed
    }

    /// Earliest time (s) at which the length travelled reaches `s` mm (bisection; the length is
    /// non-decreasing in time).
    pub fn time_at_length(&self, s: f64) -> f64 {
        let k = self.section_at_length(s);
        let sec = &self.sections[k];
        let (mut lo, mut hi) = (0.0, sec.duration);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if sec.s0 + sec.at(mid).0.p < s {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        sec.t0 + hi
    }

    fn section_at_length(&self, s: f64) -> usize {
        let mut k = 0;
        while k + 1 < self.m && self.sections[k + 1].s0 <= s {
            k += 1;
        }
        k
    }

    /// The motion at time `t` s (clamped to `[0, duration]`; at rest at the end pose exactly
    /// from the duration on). Does not allocate.
    pub fn sample(&self, t: f64) -> CompositeSample {
        let total = self.path.length();
        if t >= self.duration {
            let n = self.path.n;
            return CompositeSample {
                pose: self.path.end(),
                velocity: Pose::default(),
                s: total,
                speed: 0.0,
                acceleration: 0.0,
                jerk: 0.0,
                segment: n.saturating_sub(1),
            };
        }
        let t = t.max(0.0);
        // Binary search of the section.
        let (mut lo, mut hi) = (0, self.m);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if self.sections[mid].t0 <= t {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let sec = &self.sections[lo];
        let (st, j) = sec.at(t - sec.t0);
        let s = (sec.s0 + st.p.clamp(0.0, sec.len)).min(total);
        let segment = self.path.segment_at(s);
        let (pose, d) = self.path.segs[segment].sample(s - self.path.cum[segment]);
        let v = st.v.max(0.0);
        CompositeSample {
            pose,
            velocity: Pose::new(d.x * v, d.y * v, d.phi * v),
            s,
            speed: v,
            acceleration: st.a,
            jerk: j,
            segment,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn speed_change_length_closed_forms() {
        // Acceleration plateau: dv = 10, amax 20, jmax 100 -> t = 0.5 + 0.2.
        assert!((speed_change_length(0.0, 10.0, 20.0, 100.0) - 5.0 * 0.7).abs() < 1e-12);
        // No plateau: dv = 1 -> t = 2 sqrt(0.01) = 0.2.
        assert!((speed_change_length(2.0, 3.0, 20.0, 100.0) - 2.5 * 0.2).abs() < 1e-12);
        assert_eq!(speed_change_length(4.0, 4.0, 1.0, 1.0), 0.0);
    }

    #[test]
    fn blended_square_corner_is_tangent() {
        let v = [
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(10.0, 0.0, 0.0),
            Pose::new(10.0, 10.0, 0.0),
        ];
        let c = CompositePath::polyline(&v, 2.0).unwrap();
        assert_eq!(c.len(), 3);
        let arc = &c.segments()[1];
        assert_eq!(arc.radius(), Some(2.0));
        assert_eq!(arc.source(), SegmentSource::Blend(0));
        assert!(arc.start().max_diff(&Pose::new(8.0, 0.0, 0.0)) < 1e-12);
        assert!(arc.end().max_diff(&Pose::new(10.0, 2.0, 0.0)) < 1e-12);
        assert!(c.junction_is_smooth(1) && c.junction_is_smooth(2));
        assert!((c.length() - (8.0 + 8.0 + PI)).abs() < 1e-12);
        assert_eq!(c.end(), v[2]);
        // Sharp without a radius.
        let s = CompositePath::polyline(&v, 0.0).unwrap();
        assert!((s.junction_angle(1) - PI / 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_blend_with_a_changing_orientation_rate_is_not_smooth() {
        // The first line rotates, the second does not: the tangents differ in the combined
        // metric even after blending, so the motion stops at the blend arc's ends.
        let v = [
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(10.0, 0.0, 0.2),
            Pose::new(10.0, 10.0, 0.2),
        ];
        let c = CompositePath::polyline(&v, 2.0).unwrap();
        assert_eq!(c.len(), 3);
        assert!(!c.junction_is_smooth(1));
        let m = CompositeMotion::plan(
            &c,
            &CompositeLimits {
                vmax: 20.0,
                amax: 100.0,
                jmax: 1000.0,
            },
        )
        .unwrap();
        assert_eq!(m.speed_at_segment_start(1), 0.0);
        assert!(m.sample(1e9).pose.max_diff(&v[2]) == 0.0);
    }

    #[test]
    fn too_large_radius_is_reduced_to_half_the_shorter_line() {
        let v = [
            Pose::new(0.0, 0.0, 0.0),
            Pose::new(4.0, 0.0, 0.0),
            Pose::new(4.0, 10.0, 0.0),
        ];
        let c = CompositePath::polyline(&v, 100.0).unwrap();
        assert!((c.segments()[1].radius().unwrap() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn arcs_and_lines_chain_and_errors_name_the_segment() {
        let mut c = CompositePath::new(Pose::new(0.0, -10.0, 0.0)).unwrap();
        c.line_to(Pose::new(10.0, -10.0, 0.0), None).unwrap();
        c.arc_around(10.0, 0.0, PI, 0.0, None).unwrap();
        assert!(c.junction_is_smooth(1));
        assert!(c.end().max_diff(&Pose::new(10.0, 10.0, 0.0)) < 1e-12);
        assert_eq!(
            c.line_to(c.end(), None),
            Err(CompositeError::ZeroLength { segment: 2 })
        );
        assert_eq!(
            c.arc_around(10.0, 10.0, 1.0, 0.0, None),
            Err(CompositeError::ZeroRadius { segment: 2 })
        );
        assert!(c.line_to(Pose::new(f64::NAN, 0.0, 0.0), None).is_err());
        assert!(c.line_to(Pose::new(0.0, 10.0, 0.0), Some(-1.0)).is_err());
    }
}
