//! Execution: a torque-limited joint servo running a trajectory on the arm's dynamics.
//!
//! Job: every `control_dt_s` (1 ms), command computed-torque feedforward plus PID feedback,
//! tau = M(q) (qdd_d + Kd e' + Kp e + Ki int e) + h(q, qd), e = q_d - q, with the controller's
//! model of the arm and the payload it believes (the integral removes the steady error a wrong
//! gravity or friction model leaves; it holds while a drive saturates); saturate it at each joint's torque limit; integrate the
//! plant's forward dynamics (its own inertials, friction, armature and payload, which differ
//! from the model) by semi-implicit Euler. Record the tracking error, the demanded torques
//! (before saturation: what a limit check must look at) and the applied ones. Like a real
//! controller, trip a protective stop when the tracking error exceeds the tolerance or a joint
//! stays saturated longer than the trip time. After the trajectory ends, the servo holds its end
//! until the arm is in position (0.1 mrad, 10 mrad/s).
//!
//! Units: rad, rad/s, N m, s. Frames: joint space.

use serde::Serialize;

use crate::config::SimConfig;
use crate::robot::{DOF, DynamicsModel, JointVector, RobotModel};
use crate::trajectory::Motion;

/// In-position window at the end of a motion: every joint this close to its target (rad) ...
pub const IN_POSITION_RAD: f64 = 1e-4;
/// ... and slower than this [rad/s] (about 5 mm/s at the tool: the cup lands and lets go softly;
/// with friction the model does not know, the last tenths of a milliradian per second take the
/// servo's integral a long while, as on a real arm's low-bandwidth position loop).
pub const IN_POSITION_RAD_S: f64 = 0.01;

/// Servo settings.
#[derive(Debug, Clone, Copy)]
pub struct Servo {
    /// Control period (s).
    pub dt_s: f64,
    /// Proportional gain of the error dynamics [1/s^2].
    pub kp: f64,
    /// Integral gain of the error dynamics [1/s^3].
    pub ki: f64,
    /// Derivative gain of the error dynamics [1/s].
    pub kd: f64,
    /// Share of the model's friction the controller compensates (1 - the friction's uncertainty).
    pub friction_compensation: f64,
    /// Tracking error that trips a protective stop (rad).
    pub tolerance_rad: f64,
    /// Saturation time that trips a protective stop (s).
    pub saturation_trip_s: f64,
}

impl Servo {
    /// From the cell file: PID error dynamics with a triple pole at the servo bandwidth w,
    /// (s + w)^3 (critically damped; the integral removes the steady error that a model error in
    /// gravity or friction leaves).
    pub fn from_config(sim: &SimConfig) -> Self {
        let w = std::f64::consts::TAU * sim.servo_bandwidth_hz;
        Servo {
            dt_s: sim.control_dt_s,
            kp: 3.0 * w * w,
            ki: w * w * w,
            kd: 3.0 * w,
            friction_compensation: 1.0,
            tolerance_rad: sim.tracking_tolerance_deg.to_radians(),
            saturation_trip_s: sim.saturation_trip_s,
        }
    }
}

impl Servo {
    /// The servo compensating `share` of the model's friction: a controller that knows its
    /// friction model may be off by a fraction f compensates 1 - f of it.
    pub fn with_friction_compensation(mut self, share: f64) -> Self {
        self.friction_compensation = share;
        self
    }
}

/// Why the controller stopped the arm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Trip {
    /// A joint's tracking error exceeded the tolerance.
    TrackingError {
        /// Joint index (0-based).
        joint: usize,
        /// Error (rad).
        error_rad: f64,
    },
    /// A joint stayed at its torque limit too long.
    Saturation {
        /// Joint index (0-based).
        joint: usize,
        /// How long (s).
        for_s: f64,
    },
}

impl std::fmt::Display for Trip {
    /// Joints are numbered J1 to J6 and angles given in degrees, as on the controller's pendant.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Trip::TrackingError { joint, error_rad } => {
                write!(f, "J{} tracking error {:.2} deg", joint + 1, error_rad.to_degrees())
            }
            Trip::Saturation { joint, for_s } => write!(f, "J{} at its torque limit for {:.3} s", joint + 1, for_s),
        }
    }
}

/// One servo tick.
#[derive(Debug, Clone, Copy)]
pub struct Tick {
    /// Time (s).
    pub t_s: f64,
    /// Measured positions (rad).
    pub q: JointVector,
    /// Measured velocities [rad/s].
    pub qd: JointVector,
    /// Torques the controller demanded, before saturation [N m].
    pub demand_nm: JointVector,
    /// Applied (saturated) torques [N m].
    pub tau_nm: JointVector,
    /// Tracking error q_d - q (rad).
    pub error_rad: JointVector,
}

/// The arm and the servo between motions: the servo runs on, so a motion starts from where the
/// last one left the arm and with the integral the servo had built up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoState {
    /// Joint positions (rad).
    pub q: JointVector,
    /// Joint velocities [rad/s].
    pub qd: JointVector,
    /// The integral of the tracking error [rad s].
    pub error_integral: JointVector,
}

impl ServoState {
    /// The arm at rest at `q`, the integral cleared (after a reset).
    pub fn at_rest(q: JointVector) -> Self {
        ServoState {
            q,
            qd: JointVector::zeros(),
            error_integral: JointVector::zeros(),
        }
    }
}

/// What the execution did.
#[derive(Debug, Clone)]
pub struct Execution {
    /// Every tick.
    pub ticks: Vec<Tick>,
    /// Largest tracking error per joint (rad).
    pub max_error_rad: [f64; DOF],
    /// Ticks with some joint saturated.
    pub saturated_ticks: usize,
    /// Largest |demanded torque| / limit per joint: what the trajectory and the feedback asked
    /// for, before the drive's saturation clipped it.
    pub peak_demand_ratio: [f64; DOF],
    /// The protective stop, if one tripped, and when (s).
    pub trip: Option<(f64, Trip)>,
    /// The arm and the servo after the last tick (at rest, the integral cleared, after a trip).
    pub end_state: ServoState,
}

/// Runs `motion` on the arm from its start state: `model` is the controller's dynamics (the
/// payload it believes), `plant` the true one. Holds the end until the arm is in position.
pub fn execute(
    robot: &RobotModel,
    model: &DynamicsModel,
    plant: &DynamicsModel,
    servo: &Servo,
    motion: &impl Motion,
) -> Execution {
    let start = motion.at(0.0);
    let state = ServoState {
        q: start.q,
        qd: start.qd,
        error_integral: JointVector::zeros(),
    };
    execute_from(robot, model, plant, servo, motion, state, Settle::InPosition)
}

/// How the servo ends a motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Settle {
    /// It holds the end until every joint is in position (at most 0.3 s).
    InPosition,
    /// It hands over at the motion's end without waiting: the next motion continues from where
    /// the arm is.
    AtEnd,
}

/// The servo's target at `t` (s) into `motion`: past the end, the end at rest (the trajectory's
/// last sample still carries the final blend's deceleration).
#[inline]
fn target_at(motion: &impl Motion, t: f64) -> crate::trajectory::Sample {
    if t > motion.duration_s() + 1e-9 {
        let end = motion.at(motion.duration_s());
        crate::trajectory::Sample {
            qd: JointVector::zeros(),
            qdd: JointVector::zeros(),
            ..end
        }
    } else {
        motion.at(t)
    }
}

impl Servo {
    /// The protective stop the tracking errors `e` (rad) and the joints' saturation times (s)
    /// trip, if any: a tracking error first, then a saturation, the lowest joint first.
    #[inline]
    fn trip(&self, e: &JointVector, saturated_for: &[f64; DOF]) -> Option<Trip> {
        (0..DOF)
            .find(|&i| e[i].abs() > self.tolerance_rad)
            .map(|i| Trip::TrackingError {
                joint: i,
                error_rad: e[i],
            })
            .or_else(|| {
                (0..DOF)
                    .find(|&i| saturated_for[i] > self.saturation_trip_s)
                    .map(|i| Trip::Saturation {
                        joint: i,
                        for_s: saturated_for[i],
                    })
            })
    }
}

/// As [`execute`], from the arm's actual state `(q, qd)` (the servo absorbs a residual error
/// from the previous motion), ending as `settle` says ([`Settle::AtEnd`]: a continuous-path
/// junction, as between a transfer and the straight descent after it).
pub fn execute_from(
    robot: &RobotModel,
    model: &DynamicsModel,
    plant: &DynamicsModel,
    servo: &Servo,
    motion: &impl Motion,
    state: ServoState,
    settle: Settle,
) -> Execution {
    let limit = robot.torque_limit_nm();
    let ServoState {
        mut q,
        mut qd,
        error_integral: mut integral,
    } = state;
    // A duration a rounding error above a whole number of ticks ends on that tick, not one
    // past its end (where the target is the end at rest: a motion that ends moving would see a
    // step in its target velocity).
    let n = (motion.duration_s() / servo.dt_s - 1e-6).ceil().max(0.0) as usize;
    // After the motion, hold its end until every joint is in position (or give up after 0.3 s).
    let hold = match settle {
        Settle::InPosition => (0.3 / servo.dt_s).ceil() as usize,
        Settle::AtEnd => 0,
    };
    let mut ticks = Vec::with_capacity(n + hold + 1);
    let mut max_error = [0.0f64; DOF];
    let mut saturated_for = [0.0f64; DOF];
    let mut saturated_ticks = 0;
    let mut peak_demand = [0.0f64; DOF];
    for k in 0..=(n + hold) {
        let t = k as f64 * servo.dt_s;
        let d = target_at(motion, t);
        let e = d.q - q;
        let ed = d.qd - qd;
        let command = d.qdd + ed * servo.kd + e * servo.kp + integral * servo.ki;
        // Bias: Coriolis, centrifugal and gravity at the measured state, and the share of the
        // model's friction the controller is sure of (compensating more friction than the plant
        // has turns the excess into negative damping near rest: a limit cycle).
        let zero = JointVector::zeros();
        let h = model.inverse_dynamics_terms(&q, &qd, &zero, crate::robot::dynamics::Terms::NO_FRICTION)
            + JointVector::from_fn(|i, _| servo.friction_compensation * model.friction_nm(i, qd[i]));
        let m = model.mass_matrix(&q);
        let demand = m * command + h;
        let mut tau = demand;
        let mut any = false;
        for i in 0..DOF {
            peak_demand[i] = peak_demand[i].max(demand[i].abs() / limit[i]);
            if tau[i].abs() > limit[i] {
                tau[i] = tau[i].clamp(-limit[i], limit[i]);
                saturated_for[i] += servo.dt_s;
                any = true;
            } else {
                saturated_for[i] = 0.0;
            }
            max_error[i] = max_error[i].max(e[i].abs());
        }
        if any {
            saturated_ticks += 1;
        } else {
            // Anti-windup: the integral grows only while no drive is saturated.
            integral += e * servo.dt_s;
        }
        ticks.push(Tick {
            t_s: t,
            q,
            qd,
            demand_nm: demand,
            tau_nm: tau,
            error_rad: e,
        });
        if let Some(trip) = servo.trip(&e, &saturated_for) {
            return Execution {
                ticks,
                max_error_rad: max_error,
                saturated_ticks,
                peak_demand_ratio: peak_demand,
                trip: Some((t, trip)),
                end_state: ServoState::at_rest(q),
            };
        }
        if k >= n && (settle == Settle::AtEnd || (e.amax() < IN_POSITION_RAD && (d.qd - qd).amax() < IN_POSITION_RAD_S))
        {
            break;
        }
        // The plant steps with its own dynamics, friction taken implicitly (it is stiff near rest).
        let qdd = plant
            .forward_dynamics_implicit_friction(&q, &qd, &tau, servo.dt_s)
            .unwrap_or_else(JointVector::zeros);
        qd += qdd * servo.dt_s;
        q += qd * servo.dt_s;
    }
    Execution {
        ticks,
        max_error_rad: max_error,
        saturated_ticks,
        peak_demand_ratio: peak_demand,
        trip: None,
        end_state: ServoState {
            q,
            qd,
            error_integral: integral,
        },
    }
}
