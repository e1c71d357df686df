//! Particle-based skinning (T §(3), docs/methods.md §6): the mesh's inside is filled with
//! adaptive close-packed particles ([`super::fill`]); each particle is pulled by its
//! neighbours and by its bone; each mesh vertex follows its 4 nearest particles.
//!
//! **Forces** (accelerations on particle i; T's four kinds, plus one of ours):
//! - (a) a spring to each neighbour. T ([`Spring::Distance`]): toward the rest distance,
//!   `k_s μ_ij (d − L_ij) / m_i` along the pair, μ_ij the reduced mass. Ours, the default
//!   ([`Spring::Corotated`]): toward the rest offset turned by the pair's rotation,
//!   `k_s μ_ij (x_j − x_i − R_ij (X_j − X_i)) / m_i`, R_ij = ½(R_i + R_j) the mean of the two
//!   particles' rotation matrices (each the rotation part of Σ_j (x_j − x_i)(X_j − X_i)ᵀ over its
//!   neighbours, tracked from substep to substep by one round of Müller et al.'s iteration);
//! - (b) damping of the relative velocity along the pair: `c_s μ_ij ((v_j − v_i)·n) / m_i`;
//! - (c) toward the position its bone's skinning transform gives its rest position:
//!   `k_b (T_b(X_i) − x_i)`;
//! - (d) damping relative to the bone, the bone point's velocity taken as 0 (as T): `−c_b v_i`;
//! - (e, ours; 0 in T) pressure: `k_v μ_ij (J̄_ij − 1)(x_j − x_i) / m_i`, J̄ the mean of the two
//!   neighbourhoods' volume change `det(A_i B_i⁻¹)` (A as above, B its rest value), pushing
//!   neighbours apart where the body was squeezed. Zero for any rigid motion.
//!
//! **Why the defaults are not T's.** Measured on a limb of radius 0.1 twisted 180° at its
//! joint (tests/tests/skin_particles.rs): with T's distance springs a twist stretches the
//! springs between layers turned against each other, and they shorten by pulling toward the
//! axis: the particles at the joint fall to 0.2–0.4 of their radius and the joint section
//! keeps 3% of its area (LBS ½/½: 0%). Corotated springs pull such neighbours sideways
//! instead (a shear, not a shortening); a bone pull soft against the springs
//! (k_s / k_b ≈ 270) spreads the twist over several layers (T's stiff pull concentrates it
//! and pulls joint particles along the chord to targets 90° away, i.e. inward); the pressure
//! makes up the volume a bend squeezes out of the inner side; and turning vertex offsets by
//! the particle's own rotation makes the 4 proposals of a vertex at the joint agree (with
//! the bone's rotation, particles of the two bones propose points up to a rotation apart).
//! Together: joint area 0.97, volume 0.99 at 180°; a 90° bend keeps 0.98 of the volume with
//! no self-intersection (T: 0.96 and 51 crossing triangle pairs). [`ParticleParams::t_method`]
//! gives T's set. The price of the soft pull is lag: the particles trail a moving bone by
//! about `c_b / k_b` (0.13 s at the defaults) and settle in about 0.5 s.
//!
//! **Where T is thin, our choices.**
//! - *Neighbours* are fixed at fill time: pairs whose rest distance is at most
//!   [`ParticleParams::interaction_range`] × (r_i + r_j), stored as CSR lists. The rest length
//!   `L_ij` is their distance at fill (equal to r_i + r_j for touching particles of one level;
//!   across levels the nested lattices do not touch exactly), so the rest state is force-free
//!   to the last bit: no drift at rest, exact rigid motion.
//! - *Masses* are the particles' owned volumes (density 1). Springs scale with the reduced
//!   mass, so every pair has the same frequency √k_s whatever the sizes, and the time-step
//!   limit does not fall with the finest radius (it is set by k_s, k_v and the neighbour
//!   count). Bone forces are per unit mass for the same reason.
//! - *Damping along the pair only* (b): full relative-velocity damping would also brake a
//!   rigid rotation of the body.
//! - *The bone of a particle* is the bone whose rest segment is nearest (lowest index on a tie).
//! - *Integration*: T's extended leap-frog without iterations. Velocities live at half steps;
//!   the velocity-dependent forces (b), (d) need the velocity at the step, estimated by an
//!   Euler half step `v_n ≈ v_{n−½} + (h/2) a_{n−1}`; then `v_{n+½} = v_{n−½} + h a_n`,
//!   `x_{n+1} = x_n + h v_{n+½}`. One force evaluation per substep.
//! - *Bone transforms within a frame*: rotation slerped and translation lerped between the
//!   frame's start and end; substep n's forces use the transform at its start time.
//! - *Vertices* (T): the 4 particles nearest the vertex at rest (centre distance, ties by
//!   index); each proposes its position plus its rest offset to the vertex turned by its
//!   bone's rotation (T, [`VertexRotation::Bone`]) or by the particle's own rotation (the
//!   default, [`VertexRotation::Particle`]); the vertex is the mean.
//! - *Blow-up*: after each substep a particle that is non-finite or farther from its bone
//!   target than [`ParticleParams::max_deviation`] × the rest mesh's box diagonal stops the
//!   frame with [`Error::Numerical`] naming the frame, substep and particle, and suggesting
//!   more substeps. An unstable explicit step grows geometrically, so this catches it within
//!   a few substeps of leaving the stable range; the kinetic energy is reported per frame.
//!   [`time_step_limit`] finds the largest stable substep of a scene by bisection: 2.7 ms
//!   for the defaults on the limb (16 substeps per 24 fps frame; the default is 18), 2.3 ms
//!   for T's set (which damps harder; 24 substeps there).
//!
//! **Accuracy.** Rigid motion of all bones is reproduced exactly once settled (every spring at
//! rest, every particle on its target; measured 4e-6 r). The vertex error under deformation
//! is the spread of the 4 proposals, of the order of the offsets (a finest particle's radius
//! near the surface).
//!
//! **Cost.** Per substep three passes over the particles: rotations and volume change
//! (corotated springs or pressure only); the pair forces (about 10 neighbours each), each
//! pair computed once, at its lower-index end (its term is exactly antisymmetric, so the
//! other end takes it negated, bit for bit; the pressure's ½kv(J_i + J_j) − kv is summed
//! in that symmetric order, a reassociation of the former per-end sum); and a gather of
//! those in list order (with the bone's pull, its target carried from the last substep's
//! end) fused with the update. Per frame O(vertices × 4) for the mesh (plus one rotation
//! round per particle with [`VertexRotation::Particle`]). Positions, velocities and
//! rotations are SIMD-aligned (`Vec3A`, `Mat3A`). The first two passes run eight particles
//! at a time (`rotation_lanes`, `pair_lanes`: AVX2 or AVX-512 where the processor has it,
//! the same bits as one at a time): on the limb of BENCHMARKS §11 (4,936 particles, 60
//! frames, one thread, cachegrind) they took the rotations from 2,762 to 894 M
//! instructions and the pairs from 3,090 to 1,849 M, and the whole run from 7,684 to
//! 5,305 M. Memory O(particles × neighbours). Fitting the rotations inside the force pass
//! (one substep late) would save the first pass but made the defaults unstable at 18
//! substeps.
//!
//! **Determinism.** Each pair's force is written once, by its lower end's task, into its own
//! slot, and each particle gathers its pairs' forces in its neighbour list's order (no
//! scatter, no atomics); every particle is written by one task, the rotation
//! tracking runs a fixed number of rounds, and the blow-up check keeps the lowest failing
//! index: bytes are the same on any thread count.

use super::fill::{Fill, FillParams, FillReport, fill};
use super::pair_lanes::{Law, PairLanes, State};
use super::rotation_lanes::{Out, RotationLanes};
use glam::{Affine3A, Mat3A, Quat, Vec3, Vec3A};
use imprint_core::{Error, Mesh, Result};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Particles per parallel task: fixed, so the work split never depends on the thread count.
const CHUNK: usize = 256;
const _: () = assert!(CHUNK.is_multiple_of(imprint_core::lanes::LANES));

/// How a vertex's rest offset from each of its particles is turned.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum VertexRotation {
    /// By the particle's bone's rotation (T).
    Bone,
    /// By the rotation of the particle's neighbourhood (best fit of its neighbours' rest
    /// offsets to their current ones), so that at a twisted joint the proposals of particles
    /// on either side agree (beyond T).
    #[default]
    Particle,
}

/// The inter-particle spring (a).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum Spring {
    /// Toward the rest distance along the pair (T).
    Distance,
    /// Toward the rest offset turned by the pair's rotation (the mean of the two
    /// particles' rotations, each the best fit of its neighbours' rest offsets to their
    /// current ones, tracked every substep). A twist then pulls neighbours sideways instead
    /// of toward the axis, so a twisted joint keeps its section (beyond T).
    #[default]
    Corotated,
}

/// Everything the particle skinning needs besides the mesh and the bones. Every field may be
/// left out; the defaults suit a limb of radius about 0.1 m at 24 frames per second.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ParticleParams {
    /// How the rest mesh is filled with particles: finest radius (m) and number of levels.
    pub fill: FillParams,
    /// (a) Spring between neighbours: the squared angular frequency of one pair, 1/s².
    /// Default 40000 (well above `bone_stiffness`, so a twist spreads over several layers).
    pub stiffness: f32,
    /// (b) Damping of the pair's relative velocity along the pair, 1/s. Default 20 (the
    /// explicit damping bounds the step: 60 lowers the time-step limit by a fifth).
    pub damping: f32,
    /// (c) Pull toward the bone's target, per unit mass, 1/s². Default 150: soft against
    /// `stiffness`, so that a twist spreads over the joint instead of tearing it (the
    /// ratio sets the spread, about √(stiffness / bone_stiffness) particle layers).
    pub bone_stiffness: f32,
    /// (d) Damping of the velocity (the bone point's taken as 0), 1/s. Default 20 (about
    /// 0.8 of critical for the default bone pull).
    pub bone_damping: f32,
    /// Leap-frog steps per frame. Default 18 (a substep of 2.3 ms at 24 fps; the limit
    /// for the defaults is about 2.7 ms).
    pub substeps: u32,
    /// Neighbours: pairs closer at rest than this × (r_i + r_j). Default 1.2 (FCC's 12
    /// touching neighbours, plus the nearest pairs across levels).
    pub interaction_range: f32,
    /// Blow-up: a particle farther than this × the rest mesh's box diagonal from its bone's
    /// target. Default 0.5.
    pub max_deviation: f32,
    /// How vertex offsets are rotated. Default [`VertexRotation::Particle`] (T: `Bone`).
    pub vertex_rotation: VertexRotation,
    /// The spring (a). Default [`Spring::Corotated`] (T: `Distance`).
    pub spring: Spring,
    /// Pressure between neighbours where their neighbourhoods lost volume (J = det of the
    /// best-fit deformation < 1), 1/s²; 0 is off (T). Default 40000.
    pub volume_stiffness: f32,
}

impl Default for ParticleParams {
    fn default() -> Self {
        ParticleParams {
            fill: FillParams::default(),
            stiffness: 40000.0,
            damping: 20.0,
            bone_stiffness: 150.0,
            bone_damping: 20.0,
            substeps: 18,
            interaction_range: 1.2,
            max_deviation: 0.5,
            vertex_rotation: VertexRotation::Particle,
            spring: Spring::Corotated,
            volume_stiffness: 40000.0,
        }
    }
}

impl ParticleParams {
    /// T's forces and vertices as published: distance springs, no pressure, offsets turned
    /// by the bone, and a stiffer bone pull (which a distance-spring lattice needs to hold
    /// its shape). Collapses under a strong twist (see the module doc).
    pub fn t_method() -> Self {
        ParticleParams {
            damping: 60.0,
            bone_stiffness: 2500.0,
            bone_damping: 60.0,
            substeps: 24,
            vertex_rotation: VertexRotation::Bone,
            spring: Spring::Distance,
            volume_stiffness: 0.0,
            ..Default::default()
        }
    }
}

/// More substeps per frame than this is a typo.
pub const MAX_SUBSTEPS: u32 = 100_000;

impl ParticleParams {
    /// Checks every number; errors name the field.
    pub fn validate(&self) -> Result<()> {
        self.fill.validate()?;
        let non_neg = [
            ("stiffness", self.stiffness),
            ("damping", self.damping),
            ("bone_stiffness", self.bone_stiffness),
            ("bone_damping", self.bone_damping),
            ("volume_stiffness", self.volume_stiffness),
        ];
        for (name, v) in non_neg {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::Invalid(format!(
                    "{name} = {v}: must be a finite number ≥ 0"
                )));
            }
        }
        if self.bone_stiffness == 0.0 {
            return Err(Error::Invalid(
                "bone_stiffness = 0: the particles would not follow the bones; must be > 0".into(),
            ));
        }
        if self.substeps == 0 || self.substeps > MAX_SUBSTEPS {
            return Err(Error::Invalid(format!(
                "substeps = {}: must be between 1 and {MAX_SUBSTEPS}",
                self.substeps
            )));
        }
        if !(self.interaction_range.is_finite()
            && self.interaction_range >= 1.0
            && self.interaction_range <= 3.0)
        {
            return Err(Error::Invalid(format!(
                "interaction_range = {}: must be between 1 and 3 (× the sum of two radii)",
                self.interaction_range
            )));
        }
        if !(self.max_deviation.is_finite() && self.max_deviation > 0.0) {
            return Err(Error::Invalid(format!(
                "max_deviation = {}: must be > 0 (× the mesh's box diagonal)",
                self.max_deviation
            )));
        }
        Ok(())
    }
}

/// What one frame did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticleFrameMetrics {
    pub substeps: u32,
    /// Substep length, s.
    pub dt: f32,
    /// Σ ½ m v² at the frame's end (half-step velocities), density 1.
    pub kinetic_energy: f64,
    /// Largest particle speed, m/s.
    pub max_speed: f32,
    /// Largest distance of a particle from its bone's target, m.
    pub max_deviation: f32,
}

/// The particle skinning state: particles, their neighbours and bones, and the vertices' ties.
/// Serde writes all of it (a checkpoint: loaded, it steps on to the same bytes as a skin that
/// never stopped).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ParticleSkin {
    node: String,
    params: ParticleParams,
    rest_mesh: Mesh,
    report: FillReport,
    /// Rest positions.
    rest: Vec<Vec3>,
    radii: Vec<f32>,
    bone: Vec<u32>,
    /// Positions as of the last frame's end (what [`ParticleSkin::positions`] gives).
    x: Vec<Vec3>,
    /// Positions, SIMD-friendly, as the substeps move them.
    xa: Vec<Vec3A>,
    /// Velocities at the last half step.
    v: Vec<Vec3A>,
    /// Each particle's bone target at the end of the last substep (the next one's start).
    target: Vec<Vec3A>,
    /// Per pair (i < j, numbered by i then list order): the force term of the pair on i
    /// (before the mass weight), `−` of that on j.
    pair_f: Vec<Vec3A>,
    /// Per particle: the first of its pairs in `pair_f` (n + 1 entries), and the first
    /// entry of its list with j > i (its own pairs, in list order).
    pair_start: Vec<u32>,
    upper: Vec<u32>,
    /// Per neighbour entry: its pair's index in `pair_f`.
    pair_of: Vec<u32>,
    /// The velocities at the step estimated for the next force pass, `v + (h/2) a`.
    ve: Vec<Vec3A>,
    /// CSR neighbour lists: `nbr[start[i]..start[i+1]]`, with rest length and m_j / (m_i + m_j),
    /// the latter negated where j < i (the entry's pair force is stored from j's end).
    start: Vec<u32>,
    nbr: Vec<u32>,
    rest_len: Vec<f32>,
    /// Per neighbour entry: X_j − X_i.
    rest_off: Vec<Vec3A>,
    weight: Vec<f32>,
    /// Per vertex: 4 particles and the rest offsets from them to the vertex.
    vert_particles: Vec<[u32; 4]>,
    vert_offsets: Vec<[Vec3; 4]>,
    /// The bones' current rotations (the last frame's end).
    bone_rot: Vec<Quat>,
    /// Each particle's rotation, tracked every substep with [`Spring::Corotated`].
    rot: Vec<Quat>,
    rot_new: Vec<Quat>,
    /// Half each particle's rotation matrix, for the pairs' mean rotation.
    half_rot: Vec<Mat3A>,
    /// Per particle: det Σ_j (X_j − X_i)(X_j − X_i)ᵀ (None when its neighbours span no
    /// volume), and the current volume change J.
    rest_inv: Vec<Option<f32>>,
    jac: Vec<f32>,
    /// The lists again by blocks of eight particles, for the rotations' pass (built from
    /// the lists above: not in a checkpoint).
    #[serde(skip)]
    rot_lanes: RotationLanes,
    /// The own pairs by blocks of eight particles, for the pairs' pass (the same).
    #[serde(skip)]
    pair_lanes: PairLanes,
    bones: usize,
    deviation_limit: f32,
}

impl ParticleSkin {
    /// Fills the rest mesh (closed), ties particles to the nearest bone (segments `(head,
    /// tail)` at rest, in bone order) and vertices to their 4 nearest particles.
    pub fn new(rest: &Mesh, bones: &[(Vec3, Vec3)], params: &ParticleParams) -> Result<Self> {
        params.validate()?;
        if bones.is_empty() {
            return Err(Error::Invalid(
                "particle skinning: the rig has no bones".into(),
            ));
        }
        if bones.iter().any(|(h, t)| !h.is_finite() || !t.is_finite()) {
            return Err(Error::Invalid(
                "particle skinning: a bone's head or tail is not finite".into(),
            ));
        }
        let Fill {
            positions,
            radii,
            volumes,
            report,
            ..
        } = fill(&*closed_for_fill(rest)?, &params.fill)?;
        let n = positions.len();
        let bone: Vec<u32> = positions
            .par_iter()
            .map(|&p| nearest_bone(p, bones))
            .collect();
        let r_max = radii.iter().copied().fold(0.0f32, f32::max);
        let range = params.interaction_range;
        let grid = Grid::new(&positions, &rest.positions, 2.0 * range * r_max);
        let lists: Vec<Vec<(u32, f32, f32)>> = (0..n)
            .into_par_iter()
            .map(|i| {
                let p = positions[i];
                let mut out = Vec::new();
                grid.for_near(p, 1, |j| {
                    if j as usize == i {
                        return;
                    }
                    let d = p.distance(positions[j as usize]);
                    if d <= range * (radii[i] + radii[j as usize]) {
                        let w = volumes[j as usize] / (volumes[i] + volumes[j as usize]);
                        out.push((j, d, w));
                    }
                });
                out.sort_unstable_by_key(|e| e.0);
                out
            })
            .collect();
        let mut start = Vec::with_capacity(n + 1);
        let (mut nbr, mut rest_len, mut weight) = (Vec::new(), Vec::new(), Vec::new());
        start.push(0u32);
        for (i, l) in lists.iter().enumerate() {
            for &(j, d, w) in l {
                nbr.push(j);
                rest_len.push(d);
                weight.push(if j as usize > i { w } else { -w });
            }
            start.push(nbr.len() as u32);
        }
        let (vert_particles, vert_offsets): (Vec<[u32; 4]>, Vec<[Vec3; 4]>) = rest
            .positions
            .par_iter()
            .map(|&p| {
                let near = grid.nearest4(p, &positions);
                (near, near.map(|j| p - positions[j as usize]))
            })
            .unzip();
        // Each pair once, from its lower end: its number, and every entry's pair.
        let upper: Vec<u32> = (0..n)
            .map(|i| {
                let l = &nbr[start[i] as usize..start[i + 1] as usize];
                start[i] + l.partition_point(|&j| (j as usize) < i) as u32
            })
            .collect();
        let mut pair_start = Vec::with_capacity(n + 1);
        pair_start.push(0u32);
        for i in 0..n {
            pair_start.push(pair_start[i] + start[i + 1] - upper[i]);
        }
        let pair_of: Vec<u32> = (0..n)
            .flat_map(|i| (start[i]..start[i + 1]).map(move |e| (i, e as usize)))
            .map(|(i, e)| {
                let j = nbr[e] as usize;
                if j > i {
                    pair_start[i] + (e as u32 - upper[i])
                } else {
                    // The entry for i in j's list (lists are sorted and symmetric).
                    let l = &nbr[upper[j] as usize..start[j + 1] as usize];
                    let k = l.binary_search(&(i as u32)).expect("symmetric neighbours");
                    pair_start[j] + k as u32
                }
            })
            .collect();
        let diag = rest.bounds().size().length();
        let xa: Vec<Vec3A> = positions.iter().map(|&p| p.into()).collect();
        let rest_off: Vec<Vec3A> = (0..n)
            .flat_map(|i| (start[i]..start[i + 1]).map(move |e| (i, e as usize)))
            .map(|(i, e)| xa[nbr[e] as usize] - xa[i])
            .collect();
        let rest_inv: Vec<Option<f32>> = (0..n)
            .into_par_iter()
            .map(|i| {
                let r = start[i] as usize..start[i + 1] as usize;
                let b = neighbourhood(&xa, &nbr[r.clone()], &rest_off[r], i);
                let scale = b.x_axis.length() + b.y_axis.length() + b.z_axis.length();
                let det = b.determinant();
                (det.abs() > 1e-6 * scale.powi(3)).then_some(det)
            })
            .collect();
        let rot_lanes = RotationLanes::build(&start, &nbr, &rest_off, &rest_inv);
        let pair_lanes =
            PairLanes::build([&start, &upper, &pair_start, &nbr], &rest_off, &rest_len);
        Ok(ParticleSkin {
            node: "skin".into(),
            params: params.clone(),
            rest_mesh: rest.clone(),
            report,
            rest: positions.clone(),
            radii,
            bone,
            x: positions,
            xa,
            v: vec![Vec3A::ZERO; n],
            target: vec![Vec3A::ZERO; n],
            pair_f: vec![Vec3A::ZERO; pair_start[n] as usize],
            pair_start,
            upper,
            pair_of,
            ve: vec![Vec3A::ZERO; n],
            rest_off,
            start,
            nbr,
            rest_len,
            weight,
            vert_particles,
            vert_offsets,
            bone_rot: vec![Quat::IDENTITY; bones.len()],
            rot: vec![Quat::IDENTITY; n],
            rot_new: vec![Quat::IDENTITY; n],
            half_rot: vec![Mat3A::IDENTITY * 0.5; n],
            rot_lanes,
            pair_lanes,
            rest_inv,
            jac: vec![1.0; n],
            bones: bones.len(),
            deviation_limit: params.max_deviation * diag.max(1e-6),
        })
    }

    /// Puts the particles where the bones' skinning transforms `pose` carry them, at rest:
    /// the start of a run whose first pose is not the rest pose (particles left at rest would
    /// start up to a limb's length from their targets and stop the run as a blow-up on its
    /// first frame). Placed by dual-quaternion skinning with the per-particle `weights`
    /// ([`ParticleSkin::segment_weights`] or those [`ParticleSkin::bind_by_weights`] gives),
    /// smooth across the joints, where each particle's own bone alone would tear the joint
    /// open and load its springs far past their stable strain.
    pub fn place(&mut self, weights: &super::weights::Weights, pose: &[Affine3A]) -> Result<()> {
        if pose.len() != self.bones
            || weights.len() != self.rest.len()
            || pose.iter().any(|m| !m.is_finite())
        {
            return Err(Error::Invalid(format!(
                "particle skinning: {} bones and {} particles, but a pose of {} finite \
                 transforms and {} weighted particles",
                self.bones,
                self.rest.len(),
                pose.iter().filter(|m| m.is_finite()).count(),
                weights.len()
            )));
        }
        let rot: Vec<Quat> = pose
            .iter()
            .map(|m| m.to_scale_rotation_translation().1.normalize())
            .collect();
        let placed = super::blend::dqs(&self.rest, weights, pose);
        for (i, &x) in placed.iter().enumerate() {
            let b = self.bone[i] as usize;
            (self.xa[i], self.x[i]) = (x.into(), x);
            self.target[i] = pose[b].transform_point3a(self.rest[i].into());
            self.rot[i] = rot[b];
            self.half_rot[i] = Mat3A::from_quat(rot[b]) * 0.5;
        }
        self.v.fill(Vec3A::ZERO);
        self.ve.fill(Vec3A::ZERO);
        self.bone_rot = rot;
        Ok(())
    }

    /// Ties each particle to the bone that the nearest rest vertex follows most under
    /// `weights` (a file's weights: the artist's binding) instead of the nearest bone
    /// segment, which near a joint or between close limbs can pick the neighbour. The
    /// nearest vertex is the corner of the closest surface triangle nearest the particle.
    /// Returns each particle's weights, its nearest vertex's, to [`ParticleSkin::place`] it
    /// with. Call before the first frame.
    pub fn bind_by_weights(
        &mut self,
        weights: &super::weights::Weights,
    ) -> Result<super::weights::Weights> {
        if weights.len() != self.rest_mesh.positions.len() {
            return Err(Error::Invalid(format!(
                "particle skinning: {} weighted vertices for a mesh of {}",
                weights.len(),
                self.rest_mesh.positions.len()
            )));
        }
        let bvh = imprint_core::bvh::Bvh::new(&self.rest_mesh);
        let mesh = &self.rest_mesh;
        let nearest: Vec<usize> = self
            .rest
            .par_iter()
            .map(|&p| {
                let tri = mesh.triangles[bvh.closest(p).triangle as usize];
                let d = |v: u32| mesh.positions[v as usize].distance_squared(p);
                tri.into_iter()
                    .min_by(|&a, &b| d(a).total_cmp(&d(b)).then(a.cmp(&b)))
                    .expect("three corners") as usize
            })
            .collect();
        self.bone = nearest.iter().map(|&v| weights.main_bone(v)).collect();
        let lists: Vec<Vec<(u32, f32)>> = nearest.iter().map(|&v| weights.of(v).to_vec()).collect();
        super::weights::from_lists(&lists, self.bones)
    }

    /// Automatic weights of the particles over the bone `segments` (rest), to
    /// [`ParticleSkin::place`] them with when the rig carries no weights.
    pub fn segment_weights(&self, segments: &[(Vec3, Vec3)]) -> super::weights::Weights {
        super::weights::automatic(&self.rest, segments, &Default::default())
    }

    /// The node name used in errors.
    pub fn with_name(mut self, node: &str) -> Self {
        self.node = node.to_string();
        self
    }

    pub fn params(&self) -> &ParticleParams {
        &self.params
    }

    /// One frame of substeps. `start` and `end` are the bones' skinning transforms (rest
    /// point → posed point, rigid) at the frame's start and end.
    pub fn step_frame(
        &mut self,
        start: &[Affine3A],
        end: &[Affine3A],
        frame: u32,
        dt_frame: f32,
    ) -> Result<ParticleFrameMetrics> {
        self.check_frame_inputs(start, end, dt_frame)?;
        // Passes in parallel per substep: from a worker (see `on_workers`).
        imprint_core::pool::on_workers(|| self.run_frame(start, end, frame, dt_frame))
    }

    /// [`ParticleSkin::step_frame`] on checked inputs.
    fn run_frame(
        &mut self,
        start: &[Affine3A],
        end: &[Affine3A],
        frame: u32,
        dt_frame: f32,
    ) -> Result<ParticleFrameMetrics> {
        let split = |m: &Affine3A| {
            let (_, r, t) = m.to_scale_rotation_translation();
            (r.normalize(), t)
        };
        let s0: Vec<(Quat, Vec3)> = start.iter().map(split).collect();
        let s1: Vec<(Quat, Vec3)> = end.iter().map(split).collect();
        let substeps = self.params.substeps;
        let h = dt_frame / substeps as f32;
        for s in 0..substeps {
            let corotated = self.params.spring == Spring::Corotated;
            let kv = self.params.volume_stiffness;
            if corotated || kv > 0.0 {
                self.rotations_and_volumes(corotated);
            }
            self.pair_forces(corotated, kv);
            let tf_next = bone_poses(&s0, &s1, (s + 1) as f32 / substeps as f32);
            // The first substep starts from the bones at the frame's start; the others from
            // the last one's end targets.
            let first = (s == 0).then(|| bone_poses(&s0, &s1, 0.0));
            if let Some((i, dev)) = self.integrate(first.as_deref(), &tf_next, h) {
                return Err(self.blow_up(frame, i, dev, s + 1, h));
            }
        }
        self.bone_rot = s1.iter().map(|&(q, _)| q).collect();
        for (d, &p) in self.x.iter_mut().zip(&self.xa) {
            *d = p.into();
        }
        Ok(self.frame_metrics(&s1, h))
    }

    /// Refuses transforms of another bone count, non-finite ones and a frame length ≤ 0.
    fn check_frame_inputs(
        &self,
        start: &[Affine3A],
        end: &[Affine3A],
        dt_frame: f32,
    ) -> Result<()> {
        if start.len() != self.bones || end.len() != self.bones {
            return Err(Error::Invalid(format!(
                "particle skinning: {} bones, but {} start and {} end transforms",
                self.bones,
                start.len(),
                end.len()
            )));
        }
        if let Some(b) = start
            .iter()
            .chain(end)
            .position(|m| !m.is_finite())
            .map(|k| k % self.bones)
        {
            return Err(Error::Invalid(format!(
                "particle skinning: bone {b}'s skinning transform is not finite"
            )));
        }
        if !(dt_frame.is_finite() && dt_frame > 0.0) {
            return Err(Error::Invalid(format!(
                "particle skinning: frame length {dt_frame} s must be > 0"
            )));
        }
        Ok(())
    }

    /// Pass 0 of a substep: each particle's rotation (one round from the last one) and its
    /// neighbourhood's volume change J = det(A B⁻¹), eight particles at a time
    /// (`rotation_lanes`, built here after a checkpoint left it out).
    fn rotations_and_volumes(&mut self, corotated: bool) {
        if !self.rot_lanes.fits(self.xa.len()) {
            self.rot_lanes =
                RotationLanes::build(&self.start, &self.nbr, &self.rest_off, &self.rest_inv);
        }
        let (lanes, x, rot) = (&self.rot_lanes, &self.xa, &self.rot);
        self.rot_new
            .par_chunks_mut(CHUNK)
            .zip(self.jac.par_chunks_mut(CHUNK))
            .zip(self.half_rot.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((out_rot, jac), half_rot))| {
                let out = Out {
                    rot: out_rot,
                    half_rot,
                    jac,
                };
                lanes.chunk(c * CHUNK, x, rot, corotated, out);
            });
        if corotated {
            std::mem::swap(&mut self.rot, &mut self.rot_new);
        }
    }

    /// Pass 1 of a substep: each pair's force from x_n and the estimated v_n, once, from its
    /// lower end (the pair's term is exactly antisymmetric: negating both offsets negates
    /// every product, and the pressure's J̄ is summed symmetrically), eight lower ends at a
    /// time (`pair_lanes`).
    fn pair_forces(&mut self, corotated: bool, kv: f32) {
        if !self.pair_lanes.fits(self.xa.len()) {
            let lists = [&self.start, &self.upper, &self.pair_start, &self.nbr];
            self.pair_lanes =
                PairLanes::build(lists.map(|l| &l[..]), &self.rest_off, &self.rest_len);
        }
        let law = Law {
            ks: self.params.stiffness,
            cs: self.params.damping,
            kv,
            corotated,
        };
        let state = State {
            x: &self.xa,
            ve: &self.ve,
            half_rot: &self.half_rot,
            jac: &self.jac,
        };
        let (lanes, ps) = (&self.pair_lanes, &self.pair_start);
        let n = state.x.len();
        let mut parts = Vec::with_capacity(n.div_ceil(CHUNK));
        let mut tail: &mut [Vec3A] = &mut self.pair_f;
        for lo in (0..n).step_by(CHUNK) {
            let hi = (lo + CHUNK).min(n);
            let (a, b) = std::mem::take(&mut tail).split_at_mut((ps[hi] - ps[lo]) as usize);
            parts.push(a);
            tail = b;
        }
        parts.into_par_iter().enumerate().for_each(|(c, out)| {
            let lo = c * CHUNK;
            let at = [lo, CHUNK.min(n - lo), ps[lo] as usize];
            lanes.chunk(at, state, law, out);
        });
    }

    /// Pass 2 of a substep: each particle gathers its pairs' forces (list order) and its
    /// bone's, then the leap-frog update toward the bones at `tf_next` (the substep's end).
    /// `first`: the bones at the substep's start on the frame's first substep (after it, the
    /// last substep's end targets, the same transform bit for bit). Returns the lowest
    /// particle past the deviation limit, with its deviation.
    fn integrate(
        &mut self,
        first: Option<&[Affine3A]>,
        tf_next: &[Affine3A],
        h: f32,
    ) -> Option<(usize, f32)> {
        let (kb, cb) = (self.params.bone_stiffness, self.params.bone_damping);
        let limit = self.deviation_limit;
        let (rest, bone) = (&self.rest, &self.bone);
        let (st, wt, po, pf) = (&self.start, &self.weight, &self.pair_of, &self.pair_f);
        self.xa
            .par_chunks_mut(CHUNK)
            .zip(self.v.par_chunks_mut(CHUNK))
            .zip(self.ve.par_chunks_mut(CHUNK))
            .zip(self.target.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (((xs, vs), ves), tg))| {
                let mut bad = None;
                for k in 0..xs.len() {
                    let i = c * CHUNK + k;
                    let xi = xs[k];
                    let mut acc = Vec3A::ZERO;
                    let edges = st[i] as usize..st[i + 1] as usize;
                    for (&w, &p) in wt[edges.clone()].iter().zip(&po[edges]) {
                        // ±w f: the sign (j < i) is in the weight, exactly.
                        acc += w * pf[p as usize];
                    }
                    let target = match first {
                        Some(tf) => tf[bone[i] as usize].transform_point3a(rest[i].into()),
                        None => tg[k],
                    };
                    let an = acc + (kb * (target - xi) - cb * ves[k]);
                    vs[k] += h * an;
                    xs[k] += h * vs[k];
                    ves[k] = vs[k] + (0.5 * h) * an;
                    tg[k] = tf_next[bone[i] as usize].transform_point3a(rest[i].into());
                    if bad.is_none() {
                        let dev = xs[k].distance(tg[k]);
                        if dev.is_nan() || dev > limit || !vs[k].is_finite() {
                            bad = Some((i, dev));
                        }
                    }
                }
                bad
            })
            .reduce(|| None, |l, r| l.or(r))
    }

    /// The error of particle `i`, `dev` m from its bone's target after substep `substep`.
    fn blow_up(&self, frame: u32, i: usize, dev: f32, substep: u32, h: f32) -> Error {
        let (substeps, limit) = (self.params.substeps, self.deviation_limit);
        Error::Numerical {
            node: self.node.clone(),
            frame,
            message: format!(
                "particle skinning blew up: particle {i} (bone {}) is {dev} m from its \
                 bone's target after substep {substep} of {substeps} (substep {h} s), past \
                 the limit {limit} m",
                self.bone[i],
            ),
            hint: format!(
                "raise substeps (now {substeps}) or lower stiffness / damping / \
                 bone_stiffness if the time step is past the stable limit; if more \
                 substeps fail at the same frame, the bones move faster than the \
                 particles follow them: slow the pose or raise bone_stiffness"
            ),
        }
    }

    /// The frame's figures, gathered in particle order, against the bones at `s1` (the
    /// frame's end).
    fn frame_metrics(&self, s1: &[(Quat, Vec3)], h: f32) -> ParticleFrameMetrics {
        let end_tf: Vec<Affine3A> = s1
            .iter()
            .map(|&(q, t)| Affine3A::from_rotation_translation(q, t))
            .collect();
        let mut m = ParticleFrameMetrics {
            substeps: self.params.substeps,
            dt: h,
            ..Default::default()
        };
        for i in 0..self.x.len() {
            let vol = (self.radii[i] * 2.0 * std::f32::consts::SQRT_2).powi(3) / 4.0;
            let v2 = self.v[i].length_squared();
            m.kinetic_energy += 0.5 * vol as f64 * v2 as f64;
            m.max_speed = m.max_speed.max(v2.sqrt());
            let t = end_tf[self.bone[i] as usize].transform_point3(self.rest[i]);
            m.max_deviation = m.max_deviation.max(self.x[i].distance(t));
        }
        m
    }

    /// Posed vertex positions, in the rest mesh's order.
    pub fn vertices(&self) -> Vec<Vec3> {
        let rots: Option<Vec<Quat>> = match self.params.vertex_rotation {
            VertexRotation::Bone => None,
            VertexRotation::Particle => Some(self.particle_rotations()),
        };
        self.vert_particles
            .par_iter()
            .zip(&self.vert_offsets)
            .map(|(ps, os)| {
                let mut sum = Vec3::ZERO;
                for k in 0..4 {
                    let j = ps[k] as usize;
                    let q = match &rots {
                        Some(r) => r[j],
                        None => self.bone_rot[self.bone[j] as usize],
                    };
                    sum += self.x[j] + q * os[k];
                }
                sum * 0.25
            })
            .collect()
    }

    /// Each particle's rotation estimated from its neighbours: the rotation part of
    /// Σ_j (x_j − x_i)(X_j − X_i)ᵀ, found by a few fixed iterations started from its bone's.
    fn particle_rotations(&self) -> Vec<Quat> {
        (0..self.x.len())
            .into_par_iter()
            .map(|i| {
                let r = self.start[i] as usize..self.start[i + 1] as usize;
                let a = neighbourhood(&self.xa, &self.nbr[r.clone()], &self.rest_off[r], i);
                // Tracked rotations need one round to catch up with the last substep.
                match self.params.spring {
                    Spring::Corotated => extract_rotation(&a, self.rot[i], 1),
                    Spring::Distance => {
                        extract_rotation(&a, self.bone_rot[self.bone[i] as usize], 20)
                    }
                }
            })
            .collect()
    }

    /// The rest topology with the posed positions and recomputed normals.
    pub fn mesh(&self) -> Mesh {
        let mut m = self.rest_mesh.clone();
        m.positions = self.vertices();
        m.compute_normals();
        m
    }

    pub fn positions(&self) -> &[Vec3] {
        &self.x
    }

    pub fn rest_positions(&self) -> &[Vec3] {
        &self.rest
    }

    pub fn radii(&self) -> &[f32] {
        &self.radii
    }

    /// Each particle's bone.
    pub fn particle_bones(&self) -> &[u32] {
        &self.bone
    }

    /// The bones' rotations at the last frame's end (identity before the first frame): what
    /// [`VertexRotation::Bone`] turns vertex offsets by, and where
    /// [`Spring::Distance`]'s vertex rotations start.
    pub fn bone_rotations(&self) -> &[Quat] {
        &self.bone_rot
    }

    /// Neighbour pairs (each counted from both ends).
    pub fn neighbour_count(&self) -> usize {
        self.nbr.len()
    }

    pub fn fill_report(&self) -> &FillReport {
        &self.report
    }

    /// For the GPU path: the CSR lists (start, neighbour, rest length, signed mass weight),
    /// the pairs' layout (first upper entry per particle, first pair slot per particle, each
    /// entry's pair slot).
    pub(crate) fn gpu_lists(&self) -> [&[u32]; 5] {
        [
            &self.start,
            &self.nbr,
            &self.upper,
            &self.pair_start,
            &self.pair_of,
        ]
    }

    /// For the GPU path: per neighbour entry, the rest length and the signed mass weight.
    pub(crate) fn gpu_edge_values(&self) -> (&[f32], &[f32]) {
        (&self.rest_len, &self.weight)
    }

    /// For the GPU path: the substeps' positions, half-step velocities, estimated velocities.
    pub(crate) fn gpu_state(&self) -> (&[Vec3A], &[Vec3A], &[Vec3A]) {
        (&self.xa, &self.v, &self.ve)
    }

    /// For the GPU path: the blow-up distance, m.
    pub(crate) fn gpu_deviation_limit(&self) -> f32 {
        self.deviation_limit
    }

    /// For the GPU path: the number of bones.
    pub(crate) fn gpu_bone_count(&self) -> usize {
        self.bones
    }

    /// For the GPU path, to take a GPU skin's state back: the positions (as of the frame's
    /// end and as the substeps move them), half-step velocities, estimated velocities, each
    /// particle's tracked rotation, half its rotation matrix and its volume change, and the
    /// bones' rotations at the last frame's end.
    #[allow(clippy::type_complexity)]
    pub(crate) fn gpu_state_mut(
        &mut self,
    ) -> (
        &mut [Vec3],
        &mut [Vec3A],
        &mut [Vec3A],
        &mut [Vec3A],
        &mut [Quat],
        &mut [Mat3A],
        &mut [f32],
        &mut [Quat],
    ) {
        (
            &mut self.x,
            &mut self.xa,
            &mut self.v,
            &mut self.ve,
            &mut self.rot,
            &mut self.half_rot,
            &mut self.jac,
            &mut self.bone_rot,
        )
    }

    /// For the GPU path: per vertex its 4 particles and the rest offsets from them.
    pub(crate) fn gpu_vertex_ties(&self) -> (&[[u32; 4]], &[[Vec3; 4]]) {
        (&self.vert_particles, &self.vert_offsets)
    }

    /// For the GPU path: per particle its tracked rotation, half its rotation matrix, its
    /// volume change and its rest determinant; per neighbour entry its rest offset.
    #[allow(clippy::type_complexity)]
    pub(crate) fn gpu_rotation_state(
        &self,
    ) -> (&[Quat], &[Mat3A], &[f32], &[Option<f32>], &[Vec3A]) {
        (
            &self.rot,
            &self.half_rot,
            &self.jac,
            &self.rest_inv,
            &self.rest_off,
        )
    }
}

/// The range the pressure's volume change J is held to: a neighbourhood nearly flat at rest
/// (a thin part one or two particles thick: ears, a tail) has a tiny rest determinant, so a
/// small move gives a J of ±100 and a pressure force that threw Wuson's particles metres
/// in three substeps. Between 0 (collapsed or inverted: the most pressure) and 2 the force
/// is as before; beyond, it stays bounded. The GPU kernel clamps alike
/// (shaders/skin/particles.wgsl).
pub(crate) const JAC_RANGE: (f32, f32) = (0.0, 2.0);

/// The bones' rigid transforms a fraction `u` of the way from `s0` to `s1` (rotation and
/// translation each): slerp on the shorter arc, lerp.
fn bone_poses(s0: &[(Quat, Vec3)], s1: &[(Quat, Vec3)], u: f32) -> Vec<Affine3A> {
    s0.iter()
        .zip(s1)
        .map(|(&(q0, t0), &(q1, t1))| {
            let q = if q0.dot(q1) < 0.0 { -q1 } else { q1 };
            Affine3A::from_rotation_translation(q0.slerp(q, u), t0.lerp(t1, u))
        })
        .collect()
}

/// Σ_j (x_j − x_i)(X_j − X_i)ᵀ over i's neighbours: its rotation part turns rest offsets
/// into current ones.
pub(super) fn neighbourhood(x: &[Vec3A], nb: &[u32], rest_off: &[Vec3A], i: usize) -> Mat3A {
    let mut a = Mat3A::ZERO;
    for (&j, &r) in nb.iter().zip(rest_off) {
        let d = x[j as usize] - x[i];
        a += Mat3A::from_cols(d * r.x, d * r.y, d * r.z);
    }
    a
}

/// The rotation part of `a` (Müller et al.'s iteration on a quaternion, `rounds` fixed rounds
/// from `q`): deterministic, and falls back to `q` where `a` carries no rotation.
pub(super) fn extract_rotation(a: &Mat3A, mut q: Quat, rounds: u32) -> Quat {
    for _ in 0..rounds {
        let r = Mat3A::from_quat(q);
        let num = r.x_axis.cross(a.x_axis) + r.y_axis.cross(a.y_axis) + r.z_axis.cross(a.z_axis);
        let den = (r.x_axis.dot(a.x_axis) + r.y_axis.dot(a.y_axis) + r.z_axis.dot(a.z_axis)).abs()
            + 1e-20;
        let w = num / den;
        if w.length_squared() < 1e-18 {
            break;
        }
        // The turn by |w| about w, with tan(½·angle) = ½|w| in place of the sine and cosine
        // (the same direction, a shorter step for large turns; the fixed point is the same).
        let step = Quat::from_xyzw(0.5 * w.x, 0.5 * w.y, 0.5 * w.z, 1.0).normalize();
        q = (step * q).normalize();
    }
    q
}

/// The rest mesh as the fill needs it: closed, so that "inside" means something. Files split
/// vertices along UV seams and characters often have small openings (eyes, a mouth); a mesh
/// that is not closed is welded by position and its holes are filled with fans
/// ([`Mesh::close_holes`]). Only the fill sees the closed copy: the vertices stay the
/// file's. A mesh still open after that is an error naming what is left.
fn closed_for_fill(rest: &Mesh) -> Result<std::borrow::Cow<'_, Mesh>> {
    if rest.is_closed() {
        return Ok(std::borrow::Cow::Borrowed(rest));
    }
    let mut m = rest.welded();
    m.close_holes();
    if !m.is_closed() {
        return Err(Error::Invalid(
            "particle skinning: the mesh is not closed, and closing its holes did not close \
             it (a boundary loop passes through a vertex twice, or pieces overlap): the \
             particle fill needs an inside; close the mesh in a modeller, or use method: \
             Linear / DualQuaternion"
                .into(),
        ));
    }
    Ok(std::borrow::Cow::Owned(m))
}

fn nearest_bone(p: Vec3, bones: &[(Vec3, Vec3)]) -> u32 {
    let mut best = (f32::INFINITY, 0u32);
    for (b, &(h, t)) in bones.iter().enumerate() {
        let ab = t - h;
        let l2 = ab.length_squared();
        let s = if l2 > 0.0 {
            ((p - h).dot(ab) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = p.distance_squared(h + s * ab);
        if d < best.0 {
            best = (d, b as u32);
        }
    }
    best.1
}

/// A uniform grid of particle indices (cells of side `cell`), for neighbour and nearest
/// queries.
struct Grid {
    min: Vec3,
    cell: f32,
    dims: [i32; 3],
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl Grid {
    fn new(points: &[Vec3], extra: &[Vec3], cell: f32) -> Self {
        let b = imprint_core::Aabb::from_points(points.iter().chain(extra).copied());
        let cell = cell.max(b.size().max_element() / 256.0).max(1e-6);
        let dims = ((b.size() / cell).floor().as_ivec3() + 1).to_array();
        let mut g = Grid {
            min: b.min,
            cell,
            dims,
            starts: Vec::new(),
            items: Vec::new(),
        };
        let ncell = (dims[0] * dims[1] * dims[2]) as usize;
        let idx: Vec<usize> = points.iter().map(|&p| g.index(g.coord(p))).collect();
        let mut counts = vec![0u32; ncell + 1];
        for &c in &idx {
            counts[c + 1] += 1;
        }
        for c in 0..ncell {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        g.items = vec![0; points.len()];
        for (i, &c) in idx.iter().enumerate() {
            g.items[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        g.starts = counts;
        g
    }

    fn coord(&self, p: Vec3) -> [i32; 3] {
        let c = ((p - self.min) / self.cell).floor().as_ivec3().to_array();
        [0, 1, 2].map(|k| c[k].clamp(0, self.dims[k] - 1))
    }

    fn index(&self, c: [i32; 3]) -> usize {
        ((c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]) as usize
    }

    /// Calls `f` for every point in the cells within `ring` of `p`'s cell.
    fn for_near(&self, p: Vec3, ring: i32, mut f: impl FnMut(u32)) {
        let c = self.coord(p);
        self.for_block(c, ring, |s| {
            for &j in &self.items[self.starts[s] as usize..self.starts[s + 1] as usize] {
                f(j)
            }
        });
    }

    fn for_block(&self, c: [i32; 3], ring: i32, mut f: impl FnMut(usize)) {
        let lo = [0, 1, 2].map(|k| (c[k] - ring).max(0));
        let hi = [0, 1, 2].map(|k| (c[k] + ring).min(self.dims[k] - 1));
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    f(self.index([x, y, z]));
                }
            }
        }
    }

    /// The 4 points nearest `p` (distance, then index). Needs at least 1 point; repeats the
    /// last when there are fewer than 4.
    fn nearest4(&self, p: Vec3, points: &[Vec3]) -> [u32; 4] {
        let c = self.coord(p);
        let max_ring = self.dims.iter().copied().max().unwrap_or(1);
        let mut best: Vec<(f32, u32)> = Vec::new();
        for ring in 0..=max_ring {
            best.clear();
            self.for_block(c, ring, |s| {
                for &j in &self.items[self.starts[s] as usize..self.starts[s + 1] as usize] {
                    best.push((p.distance_squared(points[j as usize]), j));
                }
            });
            best.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            // Points outside the block are at least `ring` cells away (p is inside its cell,
            // or outside the grid where the clamp only moves it farther).
            let reach = ring as f32 * self.cell;
            if best.len() >= 4 && best[3].0 <= reach * reach {
                break;
            }
        }
        let mut out = [0u32; 4];
        for (k, o) in out.iter_mut().enumerate() {
            *o = best[k.min(best.len() - 1)].1;
        }
        out
    }
}

/// The largest stable substep for a scene, by bisection: `motion(t)` gives the bones'
/// skinning transforms at time t; each candidate substep `h` runs `steps` steps of length h
/// (one substep per frame) from a fresh copy of `skin`; stable means no blow-up. Searches
/// (lo, hi]; returns the largest stable h found (lo if even lo is unstable: check the result).
pub fn time_step_limit(
    skin: &ParticleSkin,
    motion: &dyn Fn(f32) -> Vec<Affine3A>,
    steps: u32,
    mut lo: f32,
    mut hi: f32,
    iterations: u32,
) -> f32 {
    let stable = |h: f32| {
        let mut s = skin.clone();
        s.params.substeps = 1;
        let mut prev = motion(0.0);
        for k in 0..steps {
            let next = motion((k + 1) as f32 * h);
            if s.step_frame(&prev, &next, k, h).is_err() {
                return false;
            }
            prev = next;
        }
        true
    };
    if stable(hi) {
        return hi;
    }
    for _ in 0..iterations {
        let mid = (lo * hi).sqrt();
        if stable(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives;

    fn bar() -> (Mesh, Vec<(Vec3, Vec3)>) {
        let m = primitives::cuboid(Vec3::new(0.3, 0.08, 0.08), 4);
        let bones = vec![
            (Vec3::new(-0.3, 0.0, 0.0), Vec3::ZERO),
            (Vec3::ZERO, Vec3::new(0.3, 0.0, 0.0)),
        ];
        (m, bones)
    }

    #[test]
    fn rest_is_exact_and_neighbours_are_symmetric() {
        let (m, bones) = bar();
        let mut s = ParticleSkin::new(&m, &bones, &ParticleParams::default()).unwrap();
        let v0 = s.vertices();
        for (a, b) in v0.iter().zip(&m.positions) {
            assert!(a.distance(*b) < 1e-5);
        }
        let id = vec![Affine3A::IDENTITY; 2];
        for f in 0..3 {
            s.step_frame(&id, &id, f, 1.0 / 24.0).unwrap();
        }
        assert_eq!(s.positions(), s.rest_positions());
        // Every pair is listed from both ends.
        let mut pairs = Vec::new();
        for i in 0..s.x.len() {
            for e in s.start[i]..s.start[i + 1] {
                pairs.push((i as u32, s.nbr[e as usize]));
            }
        }
        let mut rev: Vec<_> = pairs.iter().map(|&(a, b)| (b, a)).collect();
        pairs.sort_unstable();
        rev.sort_unstable();
        assert_eq!(pairs, rev);
        assert!(s.neighbour_count() >= 6 * s.x.len());
    }

    #[test]
    fn rotation_extraction_finds_a_rotation() {
        let q = Quat::from_rotation_x(2.5) * Quat::from_rotation_z(0.3);
        let a = Mat3A::from_quat(q) * Mat3A::from_diagonal(Vec3::new(1.2, 0.9, 1.0));
        let r = extract_rotation(&a, Quat::IDENTITY, 40);
        assert!(r.angle_between(q) < 1e-3, "{r} {q}");
    }

    #[test]
    fn bad_params_name_the_field() {
        let p = ParticleParams {
            substeps: 0,
            ..Default::default()
        };
        assert!(p.validate().unwrap_err().to_string().contains("substeps"));
        let p = ParticleParams {
            stiffness: f32::NAN,
            ..Default::default()
        };
        assert!(p.validate().unwrap_err().to_string().contains("stiffness"));
    }
}
