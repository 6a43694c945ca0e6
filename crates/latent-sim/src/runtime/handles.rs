//! Handles: spring forces a program adds, moves and removes by id, the same way for every
//! simulator ([`Backend`] is what a simulator provides for it).

use fem_core::Vec3;
use fem_core::forces::{ExternalForce, ForceKind};

use super::{RuntimeError, Surface, finite, positive};
use crate::ReducedError;

/// A grabbed set of vertices (or a force added as data), to move or release.
/// Each simulator's handles carry its own number, so that a handle used on another
/// simulator is refused instead of naming the handle there that has the same count.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Handle {
    owner: u64,
    id: u64,
}

impl std::fmt::Display for Handle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "#{}", self.id)
    }
}

/// The next simulator's number for its handles.
static NEXT_OWNER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// A handle and the force it is.
#[derive(Debug, Clone, Copy)]
struct Entry {
    handle: Handle,
    /// Index of its force in the simulator's list.
    force: usize,
    /// For a spring, d − t: the spring's offset d for a target t is t + base (ū − p for a
    /// patch with mean displacement ū grabbed at p). None for a point load.
    base: Option<Vec3>,
}

/// The handles of one simulator.
///
/// A copy (a clone of its simulator) keeps the owner, so that the handles made before the copy
/// act on both, and shares the count, so that a handle made on one after the copy is unknown to
/// the other instead of naming another force there.
#[derive(Debug, Clone)]
pub(crate) struct Handles {
    owner: u64,
    next: std::sync::Arc<std::sync::atomic::AtomicU64>,
    entries: Vec<Entry>,
}

impl Default for Handles {
    fn default() -> Self {
        Self {
            owner: NEXT_OWNER.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            next: Default::default(),
            entries: Vec::new(),
        }
    }
}

impl Handles {
    fn insert(&mut self, force: usize, base: Option<Vec3>) -> Handle {
        let handle = Handle {
            owner: self.owner,
            id: self.next.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        };
        self.entries.push(Entry {
            handle,
            force,
            base,
        });
        handle
    }

    fn find(&self, handle: Handle) -> Result<Entry, RuntimeError> {
        self.owned(handle)?;
        self.entries
            .iter()
            .find(|e| e.handle == handle)
            .copied()
            .ok_or(RuntimeError::UnknownHandle(handle))
    }

    fn owned(&self, handle: Handle) -> Result<(), RuntimeError> {
        if handle.owner == self.owner {
            Ok(())
        } else {
            Err(RuntimeError::ForeignHandle(handle))
        }
    }

    /// Forgets `handle` and returns its force's index; the forces after it move down by one.
    fn remove(&mut self, handle: Handle) -> Result<usize, RuntimeError> {
        self.owned(handle)?;
        let at = self
            .entries
            .iter()
            .position(|e| e.handle == handle)
            .ok_or(RuntimeError::UnknownHandle(handle))?;
        let force = self.entries.remove(at).force;
        for e in &mut self.entries {
            if e.force > force {
                e.force -= 1;
            }
        }
        Ok(force)
    }
}

/// What a simulator provides for its handles.
pub(crate) trait Backend {
    fn rest(&self) -> &[Vec3];
    /// The mesh's tetrahedra: a vertex none of them uses is no part of the body.
    fn tets(&self) -> &[[usize; 4]];
    /// The material's Young's modulus (Pa): with the body's size, the scale of a spring's
    /// stiffness.
    fn youngs_modulus(&self) -> f64;
    /// The pinned vertices, increasing.
    fn pinned(&self) -> &[usize];
    fn surface(&self) -> &Surface;
    /// The current displacement of vertex `v` (which exists).
    fn displacement(&self, v: usize) -> Result<Vec3, RuntimeError>;
    /// The current displacements of the surface vertices, 3 per vertex.
    fn surface_displacements(&mut self) -> &[f64];
    /// Adds a checked force last and returns its index.
    fn push_force(&mut self, force: ExternalForce) -> Result<usize, RuntimeError>;
    fn remove_force(&mut self, index: usize) -> Result<(), RuntimeError>;
    fn set_keyframes(&mut self, index: usize, keyframes: &[[f64; 4]]) -> Result<(), RuntimeError>;
    fn handles(&mut self) -> &mut Handles;
    /// Force `index` (which exists) and the simulated time now.
    fn force(&self, index: usize) -> &ExternalForce;
    fn now(&self) -> f64;
}

/// The stiffest spring, against the body's own stiffness at its size (E times its bounding-box
/// diagonal, N/m). A spring that much stiffer holds its vertices where it pulls them as firmly
/// as any stiffer one would, while its terms swamp the body's in every solve: at 1e12 times the
/// default bar's a dragged step took 100 L-BFGS iterations and a Newton fallback (0.4 s), at
/// 1e300 the energy overflowed and every step failed.
pub const MAX_SPRING_STIFFNESS: f64 = 1e6;

/// The body's own stiffness at its size, E times the bounding-box diagonal of `rest` (N/m):
/// springs up to [`MAX_SPRING_STIFFNESS`] times it are taken.
pub fn body_stiffness(rest: &[Vec3], youngs_modulus: f64) -> f64 {
    youngs_modulus * diagonal(rest)
}

/// The force that strains the body by its own size, E times the square of the bounding-box
/// diagonal of `rest` (N): point loads up to [`MAX_POINT_LOAD`] times it are taken.
pub fn body_force(rest: &[Vec3], youngs_modulus: f64) -> f64 {
    let size = diagonal(rest);
    youngs_modulus * size * size
}

/// The bounding-box diagonal of `rest` (m).
fn diagonal(rest: &[Vec3]) -> f64 {
    let (lo, hi) = rest.iter().fold(
        (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY)),
        |(lo, hi), x| (lo.inf(x), hi.sup(x)),
    );
    (hi - lo).norm()
}

/// The largest point load, against the force that strains the body by its own size (E times
/// the square of its bounding-box diagonal, N): as for springs, a load that much larger only
/// overflows the solves (a game developer's load of 1e300 N failed its first step with a
/// line-search message that named nothing).
pub const MAX_POINT_LOAD: f64 = 1e6;

/// Every value of a point load is at most [`MAX_POINT_LOAD`] times the body's own force scale.
fn point_load(
    b: &impl Backend,
    values: impl IntoIterator<Item = [f64; 3]>,
) -> Result<(), RuntimeError> {
    check_point_load(b.rest(), b.youngs_modulus(), values)
}

/// [`RuntimeError::TooLarge`] for the first of `values` (a point load's forces, N) above
/// [`MAX_POINT_LOAD`] times [`body_force`] of the body at `rest` with modulus `youngs_modulus`:
/// what `add_force` and `set_load` check, for a scene's loads before any stage runs.
pub fn check_point_load(
    rest: &[Vec3],
    youngs_modulus: f64,
    values: impl IntoIterator<Item = [f64; 3]>,
) -> Result<(), RuntimeError> {
    let body = body_force(rest, youngs_modulus);
    let limit = MAX_POINT_LOAD * body;
    for v in values {
        let load = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if load > limit {
            return Err(RuntimeError::TooLarge { load, body, limit });
        }
    }
    Ok(())
}

/// `stiffness` is positive and at most [`MAX_SPRING_STIFFNESS`] times the body's own.
fn spring_stiffness<B: Backend>(b: &B, stiffness: f64) -> Result<(), RuntimeError> {
    positive("stiffness", stiffness)?;
    let body = body_stiffness(b.rest(), b.youngs_modulus());
    let limit = MAX_SPRING_STIFFNESS * body;
    if stiffness > limit {
        return Err(RuntimeError::TooStiff {
            stiffness,
            body,
            limit,
        });
    }
    Ok(())
}

/// A limit as its error prints it (four significant digits), rounded down so that the value
/// printed passes the check: 1.00995e11 printed as 1.010e11 was refused when written back.
/// Whoever builds the error (the runtime, a scene's check) gets it, since the error's text
/// rounds.
pub(crate) fn printed_limit(limit: f64) -> f64 {
    if !(limit.is_finite() && limit > 0.0) {
        return limit;
    }
    let unit = 10f64.powi(limit.log10().floor() as i32 - 3);
    (limit / unit).floor() * unit
}

/// A spring on `vertices` (sorted, unique) with offset `offset` now and `base` (see [`Entry`]).
fn attach<B: Backend>(
    b: &mut B,
    vertices: Vec<usize>,
    stiffness: f64,
    offset: Vec3,
    base: Vec3,
) -> Result<Handle, RuntimeError> {
    let force = ExternalForce {
        kind: ForceKind::Spring,
        vertices,
        stiffness,
        keyframes: vec![[0.0, offset.x, offset.y, offset.z]],
        start: f64::NEG_INFINITY,
        end: f64::INFINITY,
    };
    let index = b.push_force(force)?;
    Ok(b.handles().insert(index, Some(base)))
}

/// Sorted, unique vertices of the body, at least one: each exists and some tetrahedron uses it
/// (a vertex the file lists and no tet uses moves nothing: a spring on it did nothing).
fn vertex_set<B: Backend>(b: &B, vertices: &[usize]) -> Result<Vec<usize>, RuntimeError> {
    let count = b.rest().len();
    if vertices.is_empty() {
        return Err(RuntimeError::NoVertices);
    }
    if let Some(&vertex) = vertices.iter().find(|&&v| v >= count) {
        return Err(RuntimeError::NoSuchVertex { vertex, count });
    }
    let mut set = vertices.to_vec();
    set.sort_unstable();
    set.dedup();
    let mut used = vec![false; count];
    for t in b.tets() {
        for &v in t {
            used[v] = true;
        }
    }
    if let Some(&vertex) = set.iter().find(|&&v| !used[v]) {
        return Err(RuntimeError::NotInBody { vertex });
    }
    Ok(set)
}

/// A grab or a load of pinned vertices only would move nothing: refused, as one of no vertex
/// is.
fn not_all_pinned<B: Backend>(b: &B, set: &[usize]) -> Result<(), RuntimeError> {
    if set.iter().all(|v| b.pinned().binary_search(v).is_ok()) {
        return Err(RuntimeError::AllPinned { count: set.len() });
    }
    Ok(())
}

pub(crate) fn grab<B: Backend>(
    b: &mut B,
    vertices: &[usize],
    stiffness: f64,
) -> Result<Handle, RuntimeError> {
    spring_stiffness(b, stiffness)?;
    let set = vertex_set(b, vertices)?;
    not_all_pinned(b, &set)?;
    let (mut mean_u, mut mean_x) = (Vec3::zeros(), Vec3::zeros());
    for &v in &set {
        mean_u += b.displacement(v)?;
        mean_x += b.rest()[v];
    }
    let n = set.len() as f64;
    let (mean_u, mean_x) = (mean_u / n, mean_x / n);
    // Grabbed at the current centroid p = X̄ + ū: base = ū − p = −X̄.
    attach(b, set, stiffness, mean_u, -mean_x)
}

pub(crate) fn grab_near<B: Backend>(
    b: &mut B,
    point: [f64; 3],
    radius: f64,
    stiffness: f64,
) -> Result<Handle, RuntimeError> {
    finite("point", point)?;
    positive("radius", radius)?;
    spring_stiffness(b, stiffness)?;
    let p = Vec3::from(point);
    // Not a per-frame path: a copy keeps the borrows simple.
    let u = b.surface_displacements().to_vec();
    let (mut set, mut mean_u, mut nearest) = (Vec::new(), Vec3::zeros(), f64::INFINITY);
    for (&v, uv) in b.surface().vertices().iter().zip(u.chunks_exact(3)) {
        let uv = Vec3::new(uv[0], uv[1], uv[2]);
        let squared = (b.rest()[v] + uv - p).norm_squared();
        nearest = nearest.min(squared);
        if squared <= radius * radius {
            set.push(v);
            mean_u += uv;
        }
    }
    if set.is_empty() {
        return Err(RuntimeError::NothingInReach {
            point,
            radius,
            nearest: nearest.sqrt(),
        });
    }
    not_all_pinned(b, &set)?;
    let mean_u = mean_u / set.len() as f64;
    attach(b, set, stiffness, mean_u, mean_u - p)
}

pub(crate) fn move_handle<B: Backend>(
    b: &mut B,
    handle: Handle,
    target: [f64; 3],
) -> Result<(), RuntimeError> {
    finite("target", target)?;
    let entry = b.handles().find(handle)?;
    let base = entry.base.ok_or(RuntimeError::NotASpring(handle))?;
    let d = Vec3::from(target) + base;
    b.set_keyframes(entry.force, &[[0.0, d.x, d.y, d.z]])
}

/// A spring handle's target now (its keyframed offset at the current time, less its base).
pub(crate) fn target<B: Backend>(b: &mut B, handle: Handle) -> Result<[f64; 3], RuntimeError> {
    let entry = b.handles().find(handle)?;
    let base = entry.base.ok_or(RuntimeError::NotASpring(handle))?;
    Ok((b.force(entry.force).value(b.now()) - base).into())
}

/// Sets a point load's total force (N) from now on.
pub(crate) fn set_load<B: Backend>(
    b: &mut B,
    handle: Handle,
    force: [f64; 3],
) -> Result<(), RuntimeError> {
    finite("load", force)?;
    let entry = b.handles().find(handle)?;
    if entry.base.is_some() {
        return Err(RuntimeError::NotAPointLoad(handle));
    }
    point_load(b, [force])?;
    b.set_keyframes(entry.force, &[[0.0, force[0], force[1], force[2]]])
}

/// The handles in the order they were made.
pub(crate) fn list<B: Backend>(b: &mut B) -> Vec<Handle> {
    b.handles().entries.iter().map(|e| e.handle).collect()
}

pub(crate) fn release<B: Backend>(b: &mut B, handle: Handle) -> Result<(), RuntimeError> {
    let index = b.handles().remove(handle)?;
    b.remove_force(index)
}

pub(crate) fn add_force<B: Backend>(
    b: &mut B,
    force: ExternalForce,
) -> Result<Handle, RuntimeError> {
    // Checked, not reordered: the order of a force's vertices is the order its terms are summed
    // in, which a replayed schedule keeps so that its trajectory is the same bit for bit.
    not_all_pinned(b, &vertex_set(b, &force.vertices)?)?;
    if !fem_core::forces::keyframes_usable(&force.keyframes) {
        return Err(ReducedError::Keyframes.into());
    }
    // Not a number, backwards, or empty: never acting (a tester's start = end = +∞ was taken).
    if force.start.is_nan() || force.end.is_nan() || force.end <= force.start {
        return Err(RuntimeError::ActiveSpan {
            start: force.start,
            end: force.end,
        });
    }
    // It acts while start ≤ t < end at the next steps' times t, all later than now.
    if force.end <= b.now() {
        return Err(RuntimeError::SpanOver {
            end: force.end,
            now: b.now(),
        });
    }
    let base = match force.kind {
        ForceKind::Spring => {
            spring_stiffness(b, force.stiffness)?;
            let centroid = force
                .vertices
                .iter()
                .fold(Vec3::zeros(), |s, &v| s + b.rest()[v])
                / force.vertices.len() as f64;
            Some(-centroid)
        }
        ForceKind::Point if force.stiffness != 0.0 => {
            return Err(RuntimeError::PointStiffness(force.stiffness));
        }
        ForceKind::Point => {
            point_load(b, force.keyframes.iter().map(|k| [k[1], k[2], k[3]]))?;
            None
        }
    };
    let index = b.push_force(force)?;
    Ok(b.handles().insert(index, base))
}
