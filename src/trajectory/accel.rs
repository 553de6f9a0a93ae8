//! The reference system's motion accelerator (OMRON, fast motion planning on the Viper 650):
//! §4.2's acceleration search, §4.3's path correction ("fold"), both kept inside the planner's
//! certified corridor, and the time-optimal bound they are measured against.
//!
//! Job: with the speeds fixed at the top, bisect each joint's acceleration until its peak torque
//! (inverse dynamics every millisecond along the blended trajectory) sits just below its limit
//! (§4.2); where J1 sets a segment's time and its acceleration is held down by its torque, insert
//! a via point with J2 and J3 folded toward the body (lower J1 inertia) and search again while
//! it pays (§4.3); re-check the blends' corridor against the collision model and stop at the via
//! points whose blends cut a corner. Also the controller's default parameters (the "before" of
//! the reference's comparison) and the TOPP-RA bound on the same path.
//!
//! The reference's and this cell's numbers are the documented constants below, named once.
//!
//! Units: rad, rad/s, rad/s^2, N m, s. Frames: joint space.

use super::retime::{Shares, toppra};
use super::torque::{TorqueProfile, torques};
use super::{Motion, MotionLimits, Trajectory};
use crate::robot::{DOF, DynamicsModel, JointVector, RobotModel};

/// §4.2 step 1: torques are evaluated on the trajectory sampled every millisecond (s).
pub const TORQUE_DT_S: f64 = 0.001;
/// §4.2 step 2: a joint's acceleration is settled when its peak torque is within this fraction
/// of its limit below the limit (and no joint is above).
pub const TORQUE_THRESHOLD: f64 = 0.05;
/// Longest time between the configurations whose chords [`check_corridor`] certifies in the
/// cell's cycle (s).
///
/// Between two samples dt apart, a joint whose acceleration stays within a deviates from the
/// chord by at most a dt^2 / 8 ([`chord_deviation_rad`]). At 10 ms with the default cell's
/// specification accelerations (`max_accel_deg_s2`) that is, per joint J1..J6:
/// 0.63, 1.00, 2.40, 3.93, 5.45, 3.27 mrad (not "below 1 mrad": only J1 and J2 are), and
/// summed over the joints with the planner's lever bounds several millimetres of robot motion,
/// more than the collision model's 2 mm margin; without the caps (`accel_cap = "none"`, the
/// default) the search goes above those accelerations where the torque allows (J1 up to about
/// 2.5 times on the reference paths), and the deviations grow with them. So chords at this
/// spacing are not enough by themselves: [`check_corridor`] certifies the straight stretches of
/// a trajectory (segments, blends from and to rest) as they are, and cuts each bent blend into
/// chords short enough that their deviation, from the blend's own accelerations whatever they
/// are, is at most [`CORRIDOR_BEND_BUDGET_M`] of robot motion, each certified with the margin
/// raised by its own deviation bound: the blended trajectory itself keeps the margin.
pub const CORRIDOR_CHECK_DT_S: f64 = 0.01;
/// Largest deviation of robot motion (m) between a bent blend and the chords [`check_corridor`]
/// certifies in its place (each chord's own bound is added to the margin it is certified with).
pub const CORRIDOR_BEND_BUDGET_M: f64 = 0.0002;
/// §4.2 step 1: the search starts from this share of each joint's specification acceleration.
const START_SHARE: f64 = 0.5;
/// The bisection's iterations at most (each one trajectory and its torques).
const SEARCH_ITERATIONS: usize = 30;
/// An acceleration at or above this share of the top of its bracket ([`accel_top_rad_s2`]: the
/// cap, or without one the torque ceiling) counts as at the top: the search does not raise it
/// further, and a fold cannot help J1.
const AT_TOP: f64 = 0.999;
/// After a stop is inserted, the search restarts from the accelerations just found, with this
/// share of them as the lower bracket (a stop changes little).
const WARM_LOWER_SHARE: f64 = 0.8;
/// The controller's default acceleration: this share of the torque limit over the worst inertia.
const DEFAULT_TORQUE_SHARE: f64 = 0.8;
/// §4.3: rounds of folding at most (each a pass over the segments).
const FOLD_ROUNDS: usize = 4;
/// §4.3 step 3: J2 and J3 fold out and back at this share of their top speed, each way within
/// half of J1's time for the segment.
const FOLD_SPEED_SHARE: f64 = 0.8;
/// §4.3: the full fold, half and a quarter of it are tried; the fastest that is safe and helps
/// is kept.
const FOLD_SHARES: [f64; 3] = [1.0, 0.5, 0.25];
/// Step of the central differences of J1's inertia M11 in J2 and J3 (rad).
const M11_STEP_RAD: f64 = 1e-4;
/// A fold is kept only if it shortens the motion by more than this (s).
const MIN_FOLD_GAIN_S: f64 = 1e-6;

/// The controller's default parameters: top speeds from the data sheet, and one acceleration
/// setting safe for the worst posture at maximum payload: per joint, 80 % of the torque limit over
/// the largest diagonal inertia found over `samples` seeded random postures with a `payload_kg`
/// point mass at the tool tip, capped at the specification acceleration.
pub fn default_limits(
    robot: &RobotModel,
    hand: &crate::robot::Payload,
    payload_kg: f64,
    samples: usize,
) -> MotionLimits {
    use rand::RngExt;
    let part = crate::robot::Payload::point(
        (payload_kg - hand.mass_kg).max(0.0),
        robot.flange_from_tool.translation.vector,
    );
    let d = robot.dynamics(&hand.combined(&part));
    let mut rng = crate::rng::stream(0, "default-limits");
    let mut worst = [0.0f64; DOF];
    for _ in 0..samples {
        let q = JointVector::from_fn(|i, _| rng.random_range(robot.joints[i].lower_rad..robot.joints[i].upper_rad));
        let m = d.mass_matrix(&q);
        for (i, w) in worst.iter_mut().enumerate() {
            *w = w.max(m[(i, i)]);
        }
    }
    MotionLimits {
        vel_rad_s: robot.max_vel_rad_s(),
        accel_rad_s2: JointVector::from_fn(|i, _| {
            (DEFAULT_TORQUE_SHARE * robot.joints[i].torque_limit_nm / worst[i]).min(robot.joints[i].max_accel_rad_s2)
        }),
    }
}

/// Per joint, the top of the acceleration search's bracket along the path through `via`
/// [rad/s^2].
///
/// With a cap ([`RobotModel::accel_cap_rad_s2`], `robot.drives.accel_cap = "spec"`), the cap.
/// Without one, the torque's own ceiling: the joint's torque limit over its smallest diagonal
/// inertia (armature and payload included) at the path's via points, the acceleration at which
/// its own inertia alone would take the whole limit where the path is lightest for it. Gravity,
/// friction and the joint's inertia where it accelerates (blends sit at the via points, the
/// heaviest of them counts) take their share too, so its torque binds below the ceiling; a
/// joint that reaches it unbound (its acceleration sets no blend, or the other joints' coupling
/// works for it) is not what holds the motion back and is not raised further.
pub fn accel_top_rad_s2(robot: &RobotModel, dynamics: &DynamicsModel, via: &[JointVector]) -> JointVector {
    if let Some(cap) = robot.accel_cap_rad_s2() {
        return cap;
    }
    let mut lightest = JointVector::repeat(f64::INFINITY);
    for q in via {
        let m = dynamics.mass_matrix(q);
        for i in 0..DOF {
            lightest[i] = lightest[i].min(m[(i, i)]);
        }
    }
    let limit = robot.torque_limit_nm();
    // The mass matrix is positive definite: its diagonal is positive; the floor keeps a
    // degenerate model's bracket finite.
    JointVector::from_fn(|i, _| limit[i] / lightest[i].max(MIN_INERTIA_KG_M2))
}

/// Without stretches and without a cap, [`check_corridor`] bounds a motion's accelerations by
/// their largest value at this many samples per chord.
const FALLBACK_SAMPLES_PER_CHORD: f64 = 10.0;

/// Floor of the diagonal inertia [`accel_top_rad_s2`] divides by [kg m^2].
const MIN_INERTIA_KG_M2: f64 = 1e-6;

/// Result of the acceleration search.
#[derive(Debug, Clone)]
pub struct Accelerated {
    /// The limits found.
    pub limits: MotionLimits,
    /// The trajectory under them.
    pub trajectory: Trajectory,
    /// Its torques.
    pub torques: TorqueProfile,
    /// Search iterations.
    pub iterations: usize,
}

/// The reference system's §4.2: speed fixed at the top; accelerations start at 50 % of the
/// specification; torques every `dt_s` (the reference: [`TORQUE_DT_S`]); each joint's
/// acceleration is bisected, between zero and the top of its bracket ([`accel_top_rad_s2`]: the
/// specification with `accel_cap = "spec"`, the torque's ceiling without a cap), until its peak
/// torque is within `threshold` (a fraction of the limit; the reference: [`TORQUE_THRESHOLD`])
/// below its limit, none above, or it is at the top. Returns the fastest try whose torques all
/// stay within their limits (the last try if none does).
pub fn optimise_accelerations(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    dt_s: f64,
    threshold: f64,
) -> Accelerated {
    let start = robot.max_accel_rad_s2() * START_SHARE;
    search_accelerations(robot, dynamics, via, dt_s, threshold, start, JointVector::zeros())
}

/// The bisection of [`optimise_accelerations`] from a given start and lower bracket (a warm
/// start after a small change of the path).
fn search_accelerations(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    dt_s: f64,
    threshold: f64,
    start: JointVector,
    lower: JointVector,
) -> Accelerated {
    let top = accel_top_rad_s2(robot, dynamics, via);
    let mut lo = lower.inf(&top);
    let mut hi = top;
    let mut scale = start.inf(&top);
    let vel = robot.max_vel_rad_s();
    let mut best: Option<Accelerated> = None;
    for it in 1..=SEARCH_ITERATIONS {
        let limits = MotionLimits {
            vel_rad_s: vel,
            accel_rad_s2: scale,
        };
        let trajectory = Trajectory::through(via, &limits);
        let profile = torques(dynamics, robot, &trajectory.samples(dt_s), dt_s);
        let feasible = profile.peak_ratio.iter().all(|r| *r <= 1.0);
        if feasible
            && best
                .as_ref()
                .is_none_or(|b| trajectory.duration_s < b.trajectory.duration_s)
        {
            best = Some(Accelerated {
                limits,
                trajectory: trajectory.clone(),
                torques: profile.clone(),
                iterations: it,
            });
        }
        let mut settled = true;
        for i in 0..DOF {
            let r = profile.peak_ratio[i];
            if r > 1.0 {
                hi[i] = scale[i];
                settled = false;
            } else if r < 1.0 - threshold && scale[i] < top[i] * AT_TOP {
                lo[i] = scale[i];
                settled = false;
            } else {
                continue;
            }
            scale[i] = 0.5 * (lo[i] + hi[i]);
        }
        if settled {
            break;
        }
    }
    let mut out = best.unwrap_or_else(|| {
        // Even the lowest accelerations exceed a limit (a static overload): report the last try.
        let limits = MotionLimits {
            vel_rad_s: vel,
            accel_rad_s2: scale,
        };
        let trajectory = Trajectory::through(via, &limits);
        let torques = torques(dynamics, robot, &trajectory.samples(dt_s), dt_s);
        Accelerated {
            limits,
            trajectory,
            torques,
            iterations: SEARCH_ITERATIONS,
        }
    });
    out.iterations = out.iterations.max(1);
    out
}

/// Outcome of the alternating path correction and acceleration search (the reference's §4.3).
#[derive(Debug, Clone)]
pub struct Corrected {
    /// The via points after correction (the input's if no fold helped).
    pub via: Vec<JointVector>,
    /// The accelerated trajectory along them.
    pub accelerated: Accelerated,
    /// Folds kept.
    pub folds: usize,
    /// Folds tried.
    pub tried: usize,
}

/// The reference system's §4.3, alternated with §4.2 until no gain, starting from `accelerated`
/// (the §4.2 result on `via`): in each segment where J1 needs the longest time (the segment is
/// "rate-controlled" by J1) and travels more than `min_j1_rad`, insert a via point at the middle
/// with J2 and J3 moved down the gradient of J1's inertia M11 (folding the arm toward the body),
/// by no more than they can travel out and back within J1's time for the segment; keep the fold
/// only if the re-accelerated motion is faster and, with a collision model, its new edges certify.
pub fn correct_path(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    accelerated: &Accelerated,
    collision: Option<&crate::planning::CollisionModel>,
    min_j1_rad: f64,
) -> Corrected {
    let mut current: Vec<JointVector> = via.to_vec();
    let mut best = accelerated.clone();
    let (mut folds, mut tried) = (0, 0);
    // Folding lowers J1's inertia, which only pays when J1's acceleration is held down by its
    // torque, not by its cap (or, without a cap, its ceiling).
    if best.limits.accel_rad_s2[0] >= AT_TOP * accel_top_rad_s2(robot, dynamics, via)[0] {
        return Corrected {
            via: current,
            accelerated: best,
            folds,
            tried,
        };
    }
    let vmax = robot.max_vel_rad_s();
    let mut stats = crate::planning::PlanStats::default();
    for _round in 0..FOLD_ROUNDS {
        let mut improved = false;
        let mut k = 0;
        while k + 1 < current.len() {
            let (a, b) = (current[k], current[k + 1]);
            let d = b - a;
            let t1 = d[0].abs() / vmax[0];
            let j1_limits = (1..DOF).all(|i| d[i].abs() / vmax[i] <= t1);
            if !j1_limits || d[0].abs() < min_j1_rad {
                k += 1;
                continue;
            }
            tried += 1;
            let mid = (a + b) / 2.0;
            // Gradient of M11 in (q2, q3) by central differences.
            let m11 = |q: &JointVector| dynamics.mass_matrix(q)[(0, 0)];
            let h = M11_STEP_RAD;
            let grad: Vec<f64> = [1usize, 2]
                .iter()
                .map(|&i| {
                    let (mut p, mut m) = (mid, mid);
                    p[i] += h;
                    m[i] -= h;
                    (m11(&p) - m11(&m)) / (2.0 * h)
                })
                .collect();
            let norm = grad[0].hypot(grad[1]);
            if norm < 1e-9 {
                k += 1;
                continue;
            }
            // Out and back within half of J1's segment time each way, at 80 % of top speed.
            let reach = [
                FOLD_SPEED_SHARE * vmax[1] * t1 / 2.0,
                FOLD_SPEED_SHARE * vmax[2] * t1 / 2.0,
            ];
            let step = (reach[0] / (grad[0].abs() / norm).max(1e-9)).min(reach[1] / (grad[1].abs() / norm).max(1e-9));
            // The full fold, half and a quarter of it: the fastest that is safe and helps.
            let mut kept: Option<(Vec<JointVector>, Accelerated)> = None;
            for share in FOLD_SHARES {
                let mut fold = mid;
                fold[1] -= share * step * grad[0] / norm;
                fold[2] -= share * step * grad[1] / norm;
                if !robot.within_limits(&fold, 0.0) {
                    continue;
                }
                let safe = collision
                    .is_none_or(|m| m.certify_edge(&a, &fold, &mut stats) && m.certify_edge(&fold, &b, &mut stats));
                if !safe {
                    continue;
                }
                let mut candidate = current.clone();
                candidate.insert(k + 1, fold);
                let acc = optimise_accelerations(robot, dynamics, &candidate, TORQUE_DT_S, TORQUE_THRESHOLD);
                let to_beat = kept
                    .as_ref()
                    .map_or(best.trajectory.duration_s, |(_, k)| k.trajectory.duration_s);
                let within_torque = acc.torques.peak_ratio.iter().all(|r| *r <= 1.0);
                if within_torque && acc.trajectory.duration_s < to_beat - MIN_FOLD_GAIN_S {
                    kept = Some((candidate, acc));
                }
            }
            if let Some((candidate, acc)) = kept {
                current = candidate;
                best = acc;
                folds += 1;
                improved = true;
                k += 2;
                continue;
            }
            k += 1;
        }
        if !improved {
            break;
        }
    }
    Corrected {
        via: current,
        accelerated: best,
        folds,
        tried,
    }
}

/// Per joint, the largest deviation (rad) from its chord of a motion sampled `dt_s` apart whose
/// accelerations stay within `accel_rad_s2`: a dt^2 / 8 (the interpolation error of a function
/// with a bounded second derivative, reached by a constant acceleration over the interval).
pub fn chord_deviation_rad(accel_rad_s2: &JointVector, dt_s: f64) -> JointVector {
    accel_rad_s2.abs() * (dt_s * dt_s / 8.0)
}

/// Re-checks a timed motion against the collision model: certifies that every configuration the
/// motion passes is clear by the model's margin (the blends leave the planned, certified polyline,
/// so the corridor they sweep is checked again). Returns the first time at which it fails.
///
/// With the motion's [`Stretch`](super::Stretch)es: a straight stretch is certified as the edge
/// between its ends (it passes exactly those configurations); a bent one is cut into chords at
/// most `dt_s` long and short enough that their deviation, summed over the joints with the model's
/// lever bounds, is within [`CORRIDOR_BEND_BUDGET_M`], and each chord is certified with the margin
/// raised by its deviation (every point of the robot is then clear by the margin). Without them,
/// chords every `dt_s` with the margin raised by the deviation the robot's acceleration cap
/// allows (valid for motions within it); with no cap ([`RobotModel::accel_cap_rad_s2`]), by the
/// largest acceleration the motion itself shows, sampled ten times per chord (a motion whose
/// acceleration peaks sharply between those samples is not covered).
pub fn check_corridor(model: &crate::planning::CollisionModel, motion: &impl Motion, dt_s: f64) -> Result<(), f64> {
    let mut stats = crate::planning::PlanStats::default();
    let lever = &model.spheres.lever_m;
    let sweep_m = |bend: &JointVector, h: f64| -> f64 {
        let dev = chord_deviation_rad(bend, h);
        (0..DOF).map(|i| lever[i] * dev[i]).sum()
    };
    let Some(stretches) = motion.stretches() else {
        let bound = model.robot.accel_cap_rad_s2().unwrap_or_else(|| {
            motion
                .sampled(dt_s / FALLBACK_SAMPLES_PER_CHORD)
                .iter()
                .fold(JointVector::zeros(), |m, s| m.sup(&s.qdd.abs()))
        });
        let samples = motion.sampled(dt_s);
        for w in samples.windows(2) {
            let extra = sweep_m(&bound, w[1].t_s - w[0].t_s);
            if !model.certify_edge_with_margin(&w[0].q, &w[1].q, model.margin_m + extra, &mut stats) {
                return Err(w[0].t_s);
            }
        }
        return Ok(());
    };
    for st in stretches {
        let len = st.t1_s - st.t0_s;
        if len <= 0.0 {
            continue;
        }
        let per_s2 = sweep_m(&st.bend_rad_s2, 1.0);
        let n = if per_s2 == 0.0 {
            1
        } else {
            // Chords of length h deviate by per_s2 h^2 of robot motion.
            let h = dt_s.min((CORRIDOR_BEND_BUDGET_M / per_s2).sqrt());
            (len / h).ceil().max(1.0) as usize
        };
        let h = len / n as f64;
        let extra = per_s2 * h * h;
        let mut a = motion.at(st.t0_s);
        for k in 1..=n {
            let t = if k == n { st.t1_s } else { st.t0_s + h * k as f64 };
            let b = motion.at(t);
            if !model.certify_edge_with_margin(&a.q, &b.q, model.margin_m + extra, &mut stats) {
                return Err(a.t_s);
            }
            a = b;
        }
    }
    Ok(())
}

/// §4.2 with the blends kept inside the certified corridor: the accelerated trajectory's corridor
/// is checked every `check_dt_s` (edges between samples certified; the cell uses
/// [`CORRIDOR_CHECK_DT_S`], whose documentation bounds the chord's deviation); where it fails,
/// the via point whose blend cuts the corner becomes a stop (duplicated: the arm passes exactly
/// through it) and the search runs again, warm-started from the accelerations just found.
/// Returns the via points with their stops, the accelerated trajectory and the number of stops.
pub fn accelerate_in_corridor(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    model: &crate::planning::CollisionModel,
    check_dt_s: f64,
) -> (Vec<JointVector>, Accelerated, usize) {
    let mut via = via.to_vec();
    let mut stops = 0;
    let mut acc = optimise_accelerations(robot, dynamics, &via, TORQUE_DT_S, TORQUE_THRESHOLD);
    loop {
        if stops > 0 {
            // A stop changes little: restart the bisection from the accelerations just found.
            let prev = acc.limits.accel_rad_s2;
            acc = search_accelerations(
                robot,
                dynamics,
                &via,
                TORQUE_DT_S,
                TORQUE_THRESHOLD,
                prev,
                prev * WARM_LOWER_SHARE,
            );
        }
        match check_corridor(model, &acc.trajectory, check_dt_s) {
            Ok(()) => return (via, acc, stops),
            Err(t) if stops < via.len() => {
                let j = acc.trajectory.via_near(t);
                let dup = j.clamp(1, via.len() - 2);
                if via[dup] == via[dup + 1] || via[dup] == via[dup - 1] {
                    // Already a stop there: nothing more to take out of the blend.
                    return (via, acc, stops);
                }
                via.insert(dup, via[dup]);
                stops += 1;
            }
            Err(_) => return (via, acc, stops),
        }
    }
}

/// The time-optimal bound along a path that may stop at via points: the path is cut at every
/// stop (a duplicated via point), each stop-free piece is retimed by TOPP-RA on the geometry
/// `limits` blend it with, and the durations add up. `None` if a piece is infeasible.
pub fn optimal_duration(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    limits: &MotionLimits,
    grid: usize,
) -> Option<f64> {
    let mut total = 0.0;
    let mut start = 0;
    for k in 1..=via.len() {
        if k == via.len() || via[k] == via[k - 1] {
            let piece = &via[start..k];
            if piece.len() >= 2 {
                let path = Trajectory::through(piece, limits);
                total += toppra(robot, dynamics, &path, grid, Shares::BOUND)?.duration_s();
            }
            start = k;
        }
    }
    Some(total)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::{AccelCap, Payload};

    /// J1 turns 180 deg with the tool 25 cm above the table at 55 cm reach, the hand holding a
    /// 30 g part: the reference's kind of motion, free space.
    fn j1_half_turn(robot: &RobotModel) -> Vec<JointVector> {
        let scene = crate::config::LoadedScene::embedded_default().expect("embedded default scene");
        let home = JointVector::from(scene.scene.robot.home_rad());
        let at = |y: f64| {
            robot
                .ik_tool_nearest(
                    &crate::robot::tool_down_pose(nalgebra::Vector3::new(0.0, y, 0.25), 0.0),
                    &home,
                )
                .expect("reachable")
                .q
        };
        vec![at(0.55), at(-0.55)]
    }

    fn held_dynamics(robot: &RobotModel) -> DynamicsModel {
        let scene = crate::config::LoadedScene::embedded_default().expect("embedded default scene");
        let hand = Payload::from_gripper(&scene.scene.gripper);
        robot.dynamics(&hand.combined(&Payload::point(0.03, robot.flange_from_tool.translation.vector)))
    }

    #[test]
    fn the_brackets_top_is_the_cap_or_the_torques_ceiling() {
        let robot = crate::robot::test_support::default_robot();
        let capped = robot.with_accel_cap(AccelCap::Spec);
        let free = robot.with_accel_cap(AccelCap::TorqueOnly);
        let dynamics = held_dynamics(&robot);
        let via = j1_half_turn(&robot);
        assert_eq!(accel_top_rad_s2(&capped, &dynamics, &via), robot.max_accel_rad_s2());
        let top = accel_top_rad_s2(&free, &dynamics, &via);
        let limit = robot.torque_limit_nm();
        for i in 0..DOF {
            // The torque limit spent on the lightest via point's own inertia alone.
            let lightest = via
                .iter()
                .map(|q| dynamics.mass_matrix(q)[(i, i)])
                .fold(f64::INFINITY, f64::min);
            assert!((top[i] - limit[i] / lightest).abs() <= 1e-9 * top[i], "J{}", i + 1);
            // At that acceleration the joint's own inertia alone takes its whole limit.
            assert!(lightest * top[i] >= limit[i] * (1.0 - 1e-12));
        }
        // J1 over this reach is lighter than the worst posture the specification assumes.
        assert!(top[0] > robot.joints[0].max_accel_rad_s2, "{top}");
    }

    /// Above the specification caps: where the cap held J1 back, the search without it goes above the
    /// cap, its peak torque lands within the threshold below the limit, and the motion is faster;
    /// the negative control: 10 % more acceleration than found exceeds a torque limit.
    #[test]
    fn without_the_cap_the_search_goes_above_it_until_the_torque_binds() {
        let robot = crate::robot::test_support::default_robot();
        let capped = robot.with_accel_cap(AccelCap::Spec);
        let free = robot.with_accel_cap(AccelCap::TorqueOnly);
        let dynamics = held_dynamics(&robot);
        let via = j1_half_turn(&robot);
        let spec = robot.max_accel_rad_s2();
        let before = optimise_accelerations(&capped, &dynamics, &via, TORQUE_DT_S, TORQUE_THRESHOLD);
        assert!(
            before.limits.accel_rad_s2[0] >= AT_TOP * spec[0] && before.torques.peak_ratio[0] < 1.0 - TORQUE_THRESHOLD,
            "the cap should bind J1 here: {} of spec, torque {:.3}",
            before.limits.accel_rad_s2[0] / spec[0],
            before.torques.peak_ratio[0]
        );
        let after = optimise_accelerations(&free, &dynamics, &via, TORQUE_DT_S, TORQUE_THRESHOLD);
        assert!(
            after.limits.accel_rad_s2[0] > 1.1 * spec[0],
            "{}",
            after.limits.accel_rad_s2
        );
        assert!(
            after.torques.peak_ratio.iter().all(|r| *r <= 1.0),
            "{:?}",
            after.torques.peak_ratio
        );
        assert!(
            after.torques.peak_ratio[0] >= 1.0 - TORQUE_THRESHOLD,
            "J1 not bound by its torque: {:.3}",
            after.torques.peak_ratio[0]
        );
        assert!(after.trajectory.duration_s < before.trajectory.duration_s);
        // Re-evaluated here, sample by sample, with the drive bound.
        let limit = robot.torque_limit_nm();
        let mut worst = 0.0f64;
        for s in after.trajectory.samples(TORQUE_DT_S / 2.0) {
            let tau = dynamics.drive_torque_bound_nm(&s.q, &s.qd, &s.qdd);
            worst = worst.max((0..DOF).map(|i| tau[i] / limit[i]).fold(0.0, f64::max));
        }
        assert!(worst <= 1.0 + 1e-3, "{worst}");
        // Negative control: 10 % above what was found, a torque limit is exceeded.
        let over = Trajectory::through(
            &via,
            &MotionLimits {
                vel_rad_s: after.limits.vel_rad_s,
                accel_rad_s2: after.limits.accel_rad_s2 * 1.1,
            },
        );
        let t = torques(&dynamics, &robot, &over.samples(TORQUE_DT_S), TORQUE_DT_S);
        assert!(t.peak_ratio.iter().any(|r| *r > 1.0), "{:?}", t.peak_ratio);
    }

    /// Without a cap TOPP-RA has no acceleration rows, only speed and torque: the bound is no
    /// slower than with the caps.
    #[test]
    fn the_bound_without_caps_has_no_acceleration_rows_and_is_no_slower() {
        let robot = crate::robot::test_support::default_robot();
        let capped = robot.with_accel_cap(AccelCap::Spec);
        let free = robot.with_accel_cap(AccelCap::TorqueOnly);
        let dynamics = held_dynamics(&robot);
        let via = j1_half_turn(&robot);
        let acc = optimise_accelerations(&free, &dynamics, &via, TORQUE_DT_S, TORQUE_THRESHOLD);
        let arc = super::super::ArcPath::new(&acc.trajectory);
        let rows = |r: &RobotModel| {
            use super::super::PathConstraints;
            super::super::RobotPathConstraints::new(r, &dynamics, &arc, Shares::BOUND)
                .rows(0.5)
                .len()
        };
        assert_eq!(rows(&capped), rows(&free) + 2 * DOF);
        let with = optimal_duration(&capped, &dynamics, &via, &acc.limits, 300).expect("feasible");
        let without = optimal_duration(&free, &dynamics, &via, &acc.limits, 300).expect("feasible");
        assert!(without <= with, "{without} vs {with}");
        // The accelerator without the cap is faster than the bound that keeps to it.
        assert!(
            acc.trajectory.duration_s < with,
            "{} vs {with}",
            acc.trajectory.duration_s
        );
    }
}
