//! Straight tool lines (descent, lift, retreat) and the force on what the tool holds.
//!
//! Job: move the tool centre point along a straight line in Cartesian space with a trapezoidal
//! speed profile, joint positions by inverse kinematics every millisecond, slowed until the
//! torques stay within the limits given (less the cell's margin) and, holding a part, until what
//! the part asks of the suction cup (its specific force a - g in the turning tool's frame: pull,
//! shear and peel, [`SealBudget`]) stays within the cup's budget; and slow a blended joint
//! trajectory uniformly in time for the same reason.
//!
//! Units: m, m/s, m/s^2 for the tool; rad, rad/s, rad/s^2, N m for the joints; s.
//! Frames: tool poses are `world_from_tool`; joints in joint space.

use super::{Motion, MotionLimits, Sample, Trajectory};
use crate::geometry::SealBudget;
use crate::robot::{DOF, DynamicsModel, JointVector, RobotModel};

/// A straight line is sampled (inverse kinematics, finite differences) every millisecond (s).
const LINE_DT_S: f64 = 0.001;
/// Length of the line per radian of tool rotation, so a pure turn takes time too [m/rad].
const ROTATION_LENGTH_M_PER_RAD: f64 = 0.05;
/// Slow-downs tried before a line is given up.
const LINE_TRIES: usize = 12;
/// Each slow-down multiplies the tool acceleration by this.
const LINE_SLOWDOWN: f64 = 0.75;
/// Lowest tool acceleration a seal budget may leave [m/s^2].
const MIN_LINE_ACCEL_M_S2: f64 = 0.5;
/// Largest joint step between 1 ms samples before it counts as a branch change (rad).
const MAX_JOINT_STEP_RAD: f64 = 0.05;
/// Below this |J5| the wrist is near its singularity and J4 is kept (rad).
const WRIST_SINGULAR_RAD: f64 = 0.02;
/// A wrist fix is kept only if the tool pose still matches to this position (m) ...
const WRIST_FIX_POSITION_M: f64 = 2e-5;
/// ... and this rotation (rad).
const WRIST_FIX_ANGLE_RAD: f64 = 2e-4;
/// What the held part asks of the cup is checked on samples this far apart (s).
const FORCE_CHECK_DT_S: f64 = 0.004;
/// Slowest uniform time scale [`limit_tool_force`] tries.
const MIN_TIME_SCALE: f64 = 0.05;
/// [`limit_tool_force`] bisects its time scale to this.
const TIME_SCALE_TOLERANCE: f64 = 0.02;
/// Where gravity alone asks more of the cup than its budget, a motion may add this share of the
/// budget to what gravity asks ([`seal_overload`]).
const STATIC_SLACK: f64 = 0.05;

/// Speed and acceleration of the tool along a straight line [m/s, m/s^2].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineLimits {
    /// Top tool speed [m/s].
    pub speed_m_s: f64,
    /// Tool acceleration [m/s^2].
    pub accel_m_s2: f64,
    /// Where the exact inverse kinematics cannot follow the line (it passes the wrist's
    /// singularity, J5 = 0, where J4 and J6 would spin), the line may move the wrist joints
    /// (J4-J6) linearly from end to end, the tool centre point still on the line, as long as
    /// the tool's orientation stays within this of the line's (rad; 0: never, the line fails).
    pub wrist_deviation_max_rad: f64,
}

/// A straight tool line (descent, lift, retreat) with a trapezoidal speed profile along it,
/// sampled every `dt_s`: joint positions by inverse kinematics (nearest to the previous sample),
/// velocities and accelerations by central differences. Sampled linearly in between.
#[derive(Debug, Clone)]
pub struct LineMotion {
    dt_s: f64,
    samples: Vec<Sample>,
    /// The profile's tool acceleration after the torque check [m/s^2].
    pub accel_m_s2: f64,
    /// Where the wrist joints were interpolated (see [`straight_line`]), the farthest the
    /// tool's orientation strays from the line's (rad); `None` on an exact line.
    pub wrist_deviation_rad: Option<f64>,
}

impl Motion for LineMotion {
    fn duration_s(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.t_s)
    }
    fn at(&self, t: f64) -> Sample {
        let n = self.samples.len() - 1;
        let x = (t / self.dt_s).clamp(0.0, n as f64);
        let k = (x.floor() as usize).min(n.saturating_sub(1));
        let f = x - k as f64;
        let (a, b) = (&self.samples[k], &self.samples[(k + 1).min(n)]);
        Sample {
            t_s: t,
            q: a.q + (b.q - a.q) * f,
            qd: a.qd + (b.qd - a.qd) * f,
            qdd: a.qdd + (b.qdd - a.qdd) * f,
        }
    }
}

impl LineMotion {
    /// Joint positions at the end.
    pub fn end_q(&self) -> JointVector {
        self.samples.last().map_or_else(JointVector::zeros, |s| s.q)
    }
}

/// The straight tool line from `from` (the arm at `q_from`) to `to` under `limits`, slowed until
/// the torques (with `dynamics`' payload, friction at its worst near rest) stay within `robot`'s
/// limits (the cell passes them less its torque margin, which the servo's feedback and the
/// plant's model error need) and, with `seal`, what a part on the suction cup asks of it within
/// its budget (the line's acceleration bounded, before the torques are checked, so that it holds
/// at nine rotations along the line, accelerating and braking).
/// Where the inverse kinematics fails along the line (limits, singularity) or a joint would jump
/// (a branch change), the wrist joints are interpolated within `limits.wrist_deviation_max_rad`
/// (J4-J6 linearly from end to end, J1-J3 keeping the tool centre point on the line); `None` if
/// that fails too.
pub fn straight_line(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    q_from: &JointVector,
    from: &nalgebra::Isometry3<f64>,
    to: &nalgebra::Isometry3<f64>,
    limits: &LineLimits,
    seal: Option<&SealBudget>,
) -> Option<LineMotion> {
    let length = (to.translation.vector - from.translation.vector).norm()
        + ROTATION_LENGTH_M_PER_RAD * from.rotation.angle_to(&to.rotation);
    let mut accel = limits.accel_m_s2;
    if let Some(b) = seal {
        accel = line_accel_within(b, from, to, length, accel);
    }
    let limit = robot.torque_limit_nm();
    for _ in 0..LINE_TRIES {
        let v = limits.speed_m_s.min((accel * length).sqrt());
        let t_acc = v / accel;
        let duration = if length <= 1e-9 {
            LINE_DT_S
        } else {
            2.0 * t_acc + (length - v * t_acc).max(0.0) / v
        };
        let s_at = |t: f64| -> f64 {
            if length <= 1e-9 {
                return 1.0;
            }
            let t = t.clamp(0.0, duration);
            let d = if t < t_acc {
                0.5 * accel * t * t
            } else if t > duration - t_acc {
                let r = duration - t;
                length - 0.5 * accel * r * r
            } else {
                0.5 * accel * t_acc * t_acc + v * (t - t_acc)
            };
            (d / length).clamp(0.0, 1.0)
        };
        let n = (duration / LINE_DT_S).ceil() as usize;
        let s_k: Vec<f64> = (0..=n).map(|k| s_at(k as f64 * LINE_DT_S)).collect();
        let (qs, wrist_deviation_rad) = match exact_path(robot, q_from, from, to, &s_k) {
            Some(qs) => (qs, None),
            None => {
                let (qs, deviation_rad) =
                    wrist_interpolated_path(robot, q_from, from, to, &s_k, limits.wrist_deviation_max_rad)?;
                (qs, Some(deviation_rad))
            }
        };
        let samples: Vec<Sample> = (0..=n)
            .map(|k| {
                let (a, b) = (qs[k.saturating_sub(1)], qs[(k + 1).min(n)]);
                let qd = if k == 0 || k == n {
                    JointVector::zeros()
                } else {
                    (b - a) / (2.0 * LINE_DT_S)
                };
                // At the ends (at rest) the acceleration the first and last step take, so the
                // servo's feedforward starts and stops the line on its first and last tick (a
                // zero there left the drives a step behind: the feedback then asked up to 160 %
                // of a wrist's torque to catch up).
                let qdd = if n == 0 {
                    JointVector::zeros()
                } else if k == 0 {
                    (qs[1] - qs[0]) * (2.0 / (LINE_DT_S * LINE_DT_S))
                } else if k == n {
                    (qs[n - 1] - qs[n]) * (2.0 / (LINE_DT_S * LINE_DT_S))
                } else {
                    (b - qs[k] * 2.0 + a) / (LINE_DT_S * LINE_DT_S)
                };
                Sample {
                    t_s: k as f64 * LINE_DT_S,
                    q: qs[k],
                    qd,
                    qdd,
                }
            })
            .collect();
        let within = samples.iter().all(|s| {
            let tau = dynamics.drive_torque_bound_nm(&s.q, &s.qd, &s.qdd);
            (0..DOF).all(|i| tau[i] <= limit[i])
        });
        if within {
            return Some(LineMotion {
                dt_s: LINE_DT_S,
                samples,
                accel_m_s2: accel,
                wrist_deviation_rad,
            });
        }
        accel *= LINE_SLOWDOWN;
    }
    None
}

/// The joints along the line from `from` (the arm at `q_from`) to `to` at the path parameters
/// `s_k` (0 to 1), by inverse kinematics, each sample nearest the one before; `None` if the
/// inverse kinematics fails or a joint would jump.
fn exact_path(
    robot: &RobotModel,
    q_from: &JointVector,
    from: &nalgebra::Isometry3<f64>,
    to: &nalgebra::Isometry3<f64>,
    s_k: &[f64],
) -> Option<Vec<JointVector>> {
    let mut qs = Vec::with_capacity(s_k.len());
    let mut q = *q_from;
    for (k, s) in s_k.iter().enumerate() {
        let pose = from.lerp_slerp(to, *s);
        let mut next = robot.ik_tool_nearest(&pose, &q).ok()?.q;
        if k > 0 && next[4].abs() < WRIST_SINGULAR_RAD {
            // Near the wrist singularity (J5 ~ 0) only J4 + J6 is well determined and the
            // solver's J4 is noise: keep J4, give J6 the sum, if the pose still matches.
            let mut kept = next;
            kept[5] += next[3] - q[3];
            kept[3] = q[3];
            let err = robot.world_from_tool(&kept).inverse() * pose;
            if err.translation.vector.norm() < WRIST_FIX_POSITION_M && err.rotation.angle() < WRIST_FIX_ANGLE_RAD {
                next = kept;
            }
        }
        if k > 0 && (next - q).amax() > MAX_JOINT_STEP_RAD {
            return None;
        }
        q = next;
        qs.push(q);
    }
    Some(qs)
}

/// The line with its wrist joints interpolated, as industrial controllers offer for straight
/// lines through the wrist's singularity (Mitsubishi's MVS "3-axis XYZ", FANUC's Wjnt, KUKA's
/// joint orientation type): J4-J6 move linearly from their values at `from` (`q_from`'s) to
/// those of the solution at `to` nearest `q_from`, the arm joints J1-J3 keep the tool centre
/// point on the line ([`RobotModel::ik_tool_position_wrist_held`]), and the tool's orientation
/// drifts from the line's in between: the joints, and the largest drift (rad). `None` if that
/// drift exceeds `deviation_max_rad` (0: never tried), the arm leaves its limits or a joint would
/// jump.
fn wrist_interpolated_path(
    robot: &RobotModel,
    q_from: &JointVector,
    from: &nalgebra::Isometry3<f64>,
    to: &nalgebra::Isometry3<f64>,
    s_k: &[f64],
    deviation_max_rad: f64,
) -> Option<(Vec<JointVector>, f64)> {
    if deviation_max_rad <= 0.0 {
        return None;
    }
    let q_to = robot.ik_tool_nearest(to, q_from).ok()?.q;
    let mut largest_rad = 0.0f64;
    let mut qs = Vec::with_capacity(s_k.len());
    let mut q = *q_from;
    for (k, s) in s_k.iter().enumerate() {
        let pose = from.lerp_slerp(to, *s);
        let mut seed = q;
        for i in 3..DOF {
            seed[i] = q_from[i] + (q_to[i] - q_from[i]) * s;
        }
        let next = robot.ik_tool_position_wrist_held(&pose.translation.vector, &seed)?;
        let deviation_rad = robot.world_from_tool(&next).rotation.angle_to(&pose.rotation);
        if deviation_rad > deviation_max_rad {
            return None;
        }
        largest_rad = largest_rad.max(deviation_rad);
        if k > 0 && (next - q).amax() > MAX_JOINT_STEP_RAD {
            return None;
        }
        q = next;
        qs.push(q);
    }
    Some((qs, largest_rad))
}

/// The largest tool acceleration, at most `accel_m_s2`, with which a line from `from` to `to`
/// (`length` m of [`straight_line`]'s path) keeps what the held part asks of the cup within
/// `seal`: the line accelerates and brakes along its direction, the tool turning from `from`'s
/// rotation to `to`'s, so both signs are checked at nine rotations along the way; bisected to
/// 2 %, at least [`MIN_LINE_ACCEL_M_S2`] (a part the cup cannot hold even at rest is the grasp's
/// failure, not the line's).
fn line_accel_within(
    seal: &SealBudget,
    from: &nalgebra::Isometry3<f64>,
    to: &nalgebra::Isometry3<f64>,
    length: f64,
    accel_m_s2: f64,
) -> f64 {
    let g = nalgebra::Vector3::new(0.0, 0.0, -crate::robot::GRAVITY_M_S2);
    let travel = to.translation.vector - from.translation.vector;
    // The tool centre's acceleration per unit of the path's: its share of the path's length.
    let along = if length > 1e-9 { travel / length } else { travel * 0.0 };
    let holds = |a: f64| {
        (0..=8).all(|k| {
            let rot = from.rotation.slerp(&to.rotation, k as f64 / 8.0);
            [a, -a].iter().all(|&s| seal.load(&rot, &(along * s - g)) <= 1.0)
        })
    };
    if holds(accel_m_s2) {
        return accel_m_s2;
    }
    let (mut lo, mut hi) = (MIN_LINE_ACCEL_M_S2.min(accel_m_s2), accel_m_s2);
    while hi - lo > 0.02 * hi {
        let mid = 0.5 * (lo + hi);
        if holds(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// The specific force a - g the tool exerts on what it holds [m/s^2, world] at the middle of
/// three tool poses `dt_s` apart, the latest first (a second difference of their positions).
fn specific_force_m_s2(
    later: &nalgebra::Isometry3<f64>,
    middle: &nalgebra::Isometry3<f64>,
    earlier: &nalgebra::Isometry3<f64>,
    dt_s: f64,
) -> nalgebra::Vector3<f64> {
    let g = nalgebra::Vector3::new(0.0, 0.0, -crate::robot::GRAVITY_M_S2);
    let (l, m, e) = (
        later.translation.vector,
        middle.translation.vector,
        earlier.translation.vector,
    );
    (l - 2.0 * m + e) / (dt_s * dt_s) - g
}

/// How far what the held part asks of the cup along `motion` exceeds `seal`'s budget at worst
/// (in shares of it; at most 0: within it; minus infinity for fewer than three samples): the
/// tool centre point's specific force a - g in the tool's frame, from the forward kinematics
/// sampled every `dt_s` (second differences). Where the tool is turned so that gravity alone
/// asks more than the budget (a part hanging off a tilted cup), no slowing helps: there the
/// motion may add at most 5 % of the budget to what gravity asks (`STATIC_SLACK`), and the plant
/// decides whether the cup holds.
pub fn seal_overload(robot: &RobotModel, motion: &impl Motion, dt_s: f64, seal: &SealBudget) -> f64 {
    let p: Vec<nalgebra::Isometry3<f64>> = motion
        .sampled(dt_s)
        .iter()
        .map(|s| robot.world_from_tool(&s.q))
        .collect();
    let up = nalgebra::Vector3::new(0.0, 0.0, crate::robot::GRAVITY_M_S2);
    p.windows(3)
        .map(|w| {
            let allowed = 1f64.max(seal.load(&w[1].rotation, &up) + STATIC_SLACK);
            seal.load(&w[1].rotation, &specific_force_m_s2(&w[2], &w[1], &w[0], dt_s)) - allowed
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

/// The longest lead, at most `max_lead_s`, by which a suction cup's valve may close before
/// `motion` ends (s) with the part predicted to stay on the cup until the cup stops. Once the
/// valve closes the holding force falls linearly to zero over `release_s`; at every instant
/// from then to the end what the part asks of the cup (its specific force a - g in the tool's
/// frame, forward kinematics, second differences every `dt_s`) must stay within `seal`'s budget
/// (what the plans allow with the full seal) times the share of the force left. A multiple of
/// `dt_s`; 0 if none fits.
pub fn release_lead_s(
    robot: &RobotModel,
    motion: &impl Motion,
    dt_s: f64,
    max_lead_s: f64,
    release_s: f64,
    seal: &SealBudget,
) -> f64 {
    if max_lead_s <= 0.0 || release_s <= 0.0 {
        return 0.0;
    }
    let end_s = motion.duration_s();
    let n = (max_lead_s / dt_s + 1e-9).floor() as usize;
    // Tool positions at end - k dt for k = -1 ..= n + 1 (the arm stands still after the end).
    let pos: Vec<nalgebra::Isometry3<f64>> = (0..n + 3)
        .map(|i| {
            let t = (end_s - (i as f64 - 1.0) * dt_s).clamp(0.0, end_s);
            robot.world_from_tool(&motion.at(t).q)
        })
        .collect();
    // The share of the budget asked at end - k dt, k = 0 ..= n.
    let load: Vec<f64> = pos
        .windows(3)
        .map(|w| seal.load(&w[1].rotation, &specific_force_m_s2(&w[0], &w[1], &w[2], dt_s)))
        .collect();
    (0..=n)
        .rev()
        .find(|&lead| {
            (0..=lead).all(|k| {
                let vented = (lead - k) as f64 * dt_s / release_s;
                load[k] <= 1.0 - vented
            })
        })
        .map_or(0.0, |lead| lead as f64 * dt_s)
}

/// Slows a trajectory through `via` under `limits` uniformly in time (speeds x k, accelerations
/// x k^2, which scales the profile's time by 1/k exactly) until what the held part asks of the
/// cup stays within `seal`'s budget ([`seal_overload`] at most 0): a suction cup holds its part
/// only up to a force. Returns the trajectory and k (1 when no slowing was needed). Bisection on
/// k to 2 %.
pub fn limit_tool_force(
    robot: &RobotModel,
    via: &[JointVector],
    limits: &MotionLimits,
    seal: &SealBudget,
) -> (Trajectory, f64) {
    let at = |k: f64| {
        Trajectory::through(
            via,
            &MotionLimits {
                vel_rad_s: limits.vel_rad_s * k,
                accel_rad_s2: limits.accel_rad_s2 * (k * k),
            },
        )
    };
    let full = at(1.0);
    if seal_overload(robot, &full, FORCE_CHECK_DT_S, seal) <= 0.0 {
        return (full, 1.0);
    }
    let (mut lo, mut hi) = (MIN_TIME_SCALE, 1.0);
    while hi - lo > TIME_SCALE_TOLERANCE {
        let mid = 0.5 * (lo + hi);
        if seal_overload(robot, &at(mid), FORCE_CHECK_DT_S, seal) <= 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (at(lo), lo)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LoadedScene;
    use crate::robot::{Payload, tool_down_pose};
    use nalgebra::Vector3;

    /// A 3 cm descent at 20 m/s^2: while it decelerates the cup must pull g + 20 m/s^2 (straight
    /// down, the centre of mass at the lip: no shear, no peel), most at its stop, so the valve
    /// may close at most R (1 - (g + a) / F) before the stop (F the specific force allowed at
    /// full vacuum, R the venting time); to a check step or two.
    #[test]
    fn the_valve_closes_before_the_stop_only_as_early_as_the_venting_cup_holds_the_part() {
        let scene = LoadedScene::embedded_default().unwrap();
        let robot = RobotModel::from_scene(&scene).unwrap();
        let from = tool_down_pose(Vector3::new(0.10, 0.45, 0.08), 0.0);
        let to = tool_down_pose(Vector3::new(0.10, 0.45, 0.05), 0.0);
        let q0 = robot
            .ik_tool_nearest(&from, &JointVector::from(scene.scene.robot.home_rad()))
            .unwrap()
            .q;
        let dynamics = robot.dynamics(&Payload::from_gripper(&scene.scene.gripper));
        let accel = 20.0;
        let limits = LineLimits {
            speed_m_s: 1.0,
            accel_m_s2: accel,
            wrist_deviation_max_rad: 0.0,
        };
        let down = straight_line(&robot, &dynamics, &q0, &from, &to, &limits, None).unwrap();
        let (dt, venting_s) = (0.001, 0.06);
        let needed = crate::robot::GRAVITY_M_S2 + accel;
        // A kilogram on a cup that holds `allowed` newtons, all of it the plans' budget.
        let budget = |allowed: f64| SealBudget {
            model: crate::geometry::SuctionModel {
                cup_radius_m: 0.003,
                holding_n: allowed,
                lip_friction: 0.5,
            },
            mass_kg: 1.0,
            com_from_cup_m: Vector3::zeros(),
            com_uncertainty_m: 0.0,
            share: 1.0,
        };
        for allowed in [60.0, 120.0, 400.0] {
            let expected = venting_s * (1.0 - needed / allowed);
            let lead = release_lead_s(&robot, &down, dt, 0.06, venting_s, &budget(allowed));
            assert!(
                lead >= expected - dt - 1e-9 && lead <= expected + 2.0 * dt,
                "allowed {allowed} m/s^2: lead {:.1} ms, expected {:.1} ms",
                lead * 1e3,
                expected * 1e3
            );
        }
        // Never more than the cell allows, and none when even the stop needs all of the force.
        assert_eq!(release_lead_s(&robot, &down, dt, 0.02, venting_s, &budget(1e4)), 0.02);
        assert_eq!(
            release_lead_s(&robot, &down, dt, 0.06, venting_s, &budget(needed * 0.9)),
            0.0
        );
    }

    /// A 26 mm descent over the place tray with the tool 2.2 deg off vertical, whose straight
    /// line passes 0.4 deg from the wrist's singularity (J5 from +1.9 to -2.3 deg: J4 would
    /// turn 156 deg in a millisecond). Negative control: without the wrist interpolation there
    /// is no line. With it the tool centre point keeps to the line (measured on the forward
    /// kinematics of every sample), the tool's orientation stays within the bound, J4-J6 move
    /// linearly and the line ends at its pose.
    #[test]
    fn a_line_through_the_wrist_singularity_interpolates_the_wrist_and_keeps_the_tool_on_it() {
        let scene = LoadedScene::embedded_default().unwrap();
        let robot = RobotModel::from_scene(&scene).unwrap();
        let dynamics = robot.dynamics(&Payload::from_gripper(&scene.scene.gripper));
        let deg = |q: [f64; 6]| JointVector::from_fn(|i, _| q[i].to_radians());
        let q_from = deg([-40.94, -49.8, 225.82, 13.05, 1.86, 156.03]);
        let from = robot.world_from_tool(&q_from);
        let below = robot.world_from_tool(&deg([-40.94, -43.85, 223.89, -10.74, -2.25, 179.8]));
        // The same orientation at both ends, straight down the world's z.
        let to = nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::from(Vector3::new(
                from.translation.x,
                from.translation.y,
                below.translation.z,
            )),
            from.rotation,
        );
        let mut limits = LineLimits {
            speed_m_s: 1.0,
            accel_m_s2: 20.0,
            wrist_deviation_max_rad: 0.0,
        };
        assert!(straight_line(&robot, &dynamics, &q_from, &from, &to, &limits, None).is_none());
        limits.wrist_deviation_max_rad = 1f64.to_radians();
        let line = straight_line(&robot, &dynamics, &q_from, &from, &to, &limits, None).expect("a line");
        let (a, b) = (from.translation.vector, to.translation.vector);
        let axis = (b - a).normalize();
        let (mut off_line_m, mut tilt_rad, mut min_j5) = (0.0f64, 0.0f64, f64::INFINITY);
        for smp in &line.samples {
            let pose = robot.world_from_tool(&smp.q);
            let d = pose.translation.vector - a;
            off_line_m = off_line_m.max((d - axis * d.dot(&axis)).norm());
            tilt_rad = tilt_rad.max(pose.rotation.angle_to(&from.rotation));
            min_j5 = min_j5.min(smp.q[4].abs());
            // J4 + J6 and J5 along a straight line in the wrist's joints.
            let s = (smp.q[4] - q_from[4]) / (line.end_q()[4] - q_from[4]);
            for i in [3, 5] {
                let expected = q_from[i] + s * (line.end_q()[i] - q_from[i]);
                assert!((smp.q[i] - expected).abs() < 1e-6, "J{} off its interpolation", i + 1);
            }
        }
        assert!(
            off_line_m < 1e-5,
            "the tool centre point left the line by {off_line_m} m"
        );
        assert!(
            tilt_rad <= 1f64.to_radians() + 1e-9 && tilt_rad > 0.1f64.to_radians(),
            "tilt {tilt_rad} rad"
        );
        assert!(
            min_j5 < 0.2f64.to_radians(),
            "the wrist passes its singularity: min |J5| {min_j5}"
        );
        let end = robot.world_from_tool(&line.end_q());
        assert!((end.translation.vector - b).norm() < 1e-5 && end.rotation.angle_to(&to.rotation) < 1e-6);
    }

    /// A swing of J1 by 0.8 rad with a 30 g block on the cell's 6 mm cup, its centre of mass
    /// 15 mm below the lip: the carry's sideways acceleration asks its shear over the lip's
    /// friction and the peel of that depth, so the carry is slowed until the cup's budget holds.
    /// Negative control: the same block with its centre of mass at the lip, on a lip that grips
    /// three times as well, is slowed less.
    #[test]
    fn a_carry_is_slowed_for_the_shear_and_peel_of_a_centre_of_mass_below_the_lip() {
        let scene = LoadedScene::embedded_default().unwrap();
        let robot = RobotModel::from_scene(&scene).unwrap();
        let hand = Payload::from_gripper(&scene.scene.gripper);
        let limits = crate::trajectory::default_limits(&robot, &hand, 0.6, 200);
        let q0 = robot
            .ik_tool_nearest(
                &tool_down_pose(Vector3::new(0.35, 0.0, 0.10), 0.0),
                &JointVector::from(scene.scene.robot.home_rad()),
            )
            .unwrap()
            .q;
        let mut q1 = q0;
        q1[0] += 0.8;
        let via = [q0, q1];
        let deep = SealBudget {
            model: crate::geometry::SuctionModel::new(&scene.scene.gripper),
            mass_kg: 0.030,
            com_from_cup_m: Vector3::new(0.0, 0.0, 0.015),
            com_uncertainty_m: 0.0,
            share: 0.75,
        };
        let full = Trajectory::through(&via, &limits);
        assert!(
            seal_overload(&robot, &full, FORCE_CHECK_DT_S, &deep) > 0.0,
            "the full-speed swing asks too much"
        );
        let (slowed, k) = limit_tool_force(&robot, &via, &limits, &deep);
        assert!(k < 1.0 && k > MIN_TIME_SCALE, "time scale {k}");
        assert!(seal_overload(&robot, &slowed, FORCE_CHECK_DT_S, &deep) <= 0.0);
        let shallow = SealBudget {
            model: crate::geometry::SuctionModel {
                lip_friction: 1.5,
                ..deep.model
            },
            com_from_cup_m: Vector3::zeros(),
            ..deep
        };
        let (_, k_shallow) = limit_tool_force(&robot, &via, &limits, &shallow);
        assert!(k_shallow > k + 0.1, "shallow {k_shallow}, deep {k}");
    }
}
