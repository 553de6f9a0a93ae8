//! Execution: a torque-limited joint servo running a trajectory on the arm's dynamics.
//!
//! Job: every `control_dt_s` (1 ms), command computed-torque feedforward plus PD feedback,
//! tau = M(q) (qdd_d + Kd (qd_d - qd) + Kp (q_d - q)) + h(q, qd), with the model's payload;
//! saturate it at each joint's torque limit; integrate the arm's forward dynamics with the true
//! payload (armature and friction included) by semi-implicit Euler. Record the tracking error
//! and the applied torques. Like a real controller, trip a protective stop when the tracking
//! error exceeds the tolerance or a joint stays saturated longer than the trip time. After the
//! trajectory ends, the servo holds its end until the arm is in position (0.1 mrad).
//!
//! Units: rad, rad/s, N m, s. Frames: joint space.

use serde::Serialize;

use crate::config::SimConfig;
use crate::robot::{DOF, DynamicsModel, JointVector, RobotModel};
use crate::trajectory::Motion;

/// In-position window at the end of a motion [rad, and rad/s].
pub const IN_POSITION_RAD: f64 = 1e-4;

/// Servo settings.
#[derive(Debug, Clone, Copy)]
pub struct Servo {
    /// Control period [s].
    pub dt_s: f64,
    /// Proportional gain of the error dynamics [1/s^2].
    pub kp: f64,
    /// Derivative gain of the error dynamics [1/s].
    pub kd: f64,
    /// Tracking error that trips a protective stop [rad].
    pub tolerance_rad: f64,
    /// Saturation time that trips a protective stop [s].
    pub saturation_trip_s: f64,
}

impl Servo {
    /// From the cell file: critically damped error dynamics at the servo bandwidth.
    pub fn from_config(sim: &SimConfig) -> Self {
        let w = std::f64::consts::TAU * sim.servo_bandwidth_hz;
        Servo {
            dt_s: sim.control_dt_s,
            kp: w * w,
            kd: 2.0 * w,
            tolerance_rad: sim.tracking_tolerance_deg.to_radians(),
            saturation_trip_s: sim.saturation_trip_s,
        }
    }
}

/// Why the controller stopped the arm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Trip {
    /// A joint's tracking error exceeded the tolerance.
    TrackingError {
        /// Joint index (0-based).
        joint: usize,
        /// Error [rad].
        error_rad: f64,
    },
    /// A joint stayed at its torque limit too long.
    Saturation {
        /// Joint index (0-based).
        joint: usize,
        /// How long [s].
        for_s: f64,
    },
}

/// One servo tick.
#[derive(Debug, Clone, Copy)]
pub struct Tick {
    /// Time [s].
    pub t_s: f64,
    /// Measured positions [rad].
    pub q: JointVector,
    /// Measured velocities [rad/s].
    pub qd: JointVector,
    /// Applied (saturated) torques [N m].
    pub tau_nm: JointVector,
    /// Tracking error q_d - q [rad].
    pub error_rad: JointVector,
}

/// What the execution did.
#[derive(Debug, Clone)]
pub struct Execution {
    /// Every tick.
    pub ticks: Vec<Tick>,
    /// Largest tracking error per joint [rad].
    pub max_error_rad: [f64; DOF],
    /// Ticks with some joint saturated.
    pub saturated_ticks: usize,
    /// The protective stop, if one tripped, and when [s].
    pub trip: Option<(f64, Trip)>,
    /// Positions and velocities after the last tick [rad, rad/s] (at rest after a trip).
    pub end_state: (JointVector, JointVector),
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
    execute_from(robot, model, plant, servo, motion, (start.q, start.qd), true)
}

/// As [`execute`], from the arm's actual state `(q, qd)` (the servo absorbs a residual error
/// from the previous motion). With `settle` false the servo hands over at the motion's end
/// without waiting to be in position: the next motion continues from where the arm is (a
/// continuous-path junction, as between a transfer and the straight descent after it).
pub fn execute_from(
    robot: &RobotModel,
    model: &DynamicsModel,
    plant: &DynamicsModel,
    servo: &Servo,
    motion: &impl Motion,
    state: (JointVector, JointVector),
    settle: bool,
) -> Execution {
    let limit = robot.torque_limit_nm();
    let (mut q, mut qd) = state;
    let n = (motion.duration_s() / servo.dt_s).ceil() as usize;
    // After the motion, hold its end until every joint is in position (or give up after 0.3 s).
    let hold = if settle { (0.3 / servo.dt_s).ceil() as usize } else { 0 };
    let mut ticks = Vec::with_capacity(n + hold + 1);
    let mut max_error = [0.0f64; DOF];
    let mut saturated_for = [0.0f64; DOF];
    let mut saturated_ticks = 0;
    for k in 0..=(n + hold) {
        let t = k as f64 * servo.dt_s;
        // Past the end the target is the end at rest (the trajectory's last sample still
        // carries the final blend's deceleration).
        let d = if t > motion.duration_s() {
            let end = motion.at(motion.duration_s());
            crate::trajectory::Sample {
                qd: JointVector::zeros(),
                qdd: JointVector::zeros(),
                ..end
            }
        } else {
            motion.at(t)
        };
        let e = d.q - q;
        let ed = d.qd - qd;
        let command = d.qdd + ed * servo.kd + e * servo.kp;
        let h = model.inverse_dynamics(&q, &qd, &JointVector::zeros());
        let m = model.mass_matrix(&q);
        let mut tau = m * command + h;
        let mut any = false;
        for i in 0..DOF {
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
        }
        ticks.push(Tick {
            t_s: t,
            q,
            qd,
            tau_nm: tau,
            error_rad: e,
        });
        let trip = (0..DOF)
            .find(|&i| e[i].abs() > servo.tolerance_rad)
            .map(|i| Trip::TrackingError {
                joint: i,
                error_rad: e[i],
            })
            .or_else(|| {
                (0..DOF)
                    .find(|&i| saturated_for[i] > servo.saturation_trip_s)
                    .map(|i| Trip::Saturation {
                        joint: i,
                        for_s: saturated_for[i],
                    })
            });
        if let Some(trip) = trip {
            return Execution {
                ticks,
                max_error_rad: max_error,
                saturated_ticks,
                trip: Some((t, trip)),
                end_state: (q, JointVector::zeros()),
            };
        }
        if k >= n && (!settle || (e.amax() < IN_POSITION_RAD && (d.qd - qd).amax() < IN_POSITION_RAD)) {
            break;
        }
        // The plant's M and bias are the controller's when they are the same model: solve with them.
        let qdd = if std::ptr::eq(model, plant) {
            m.cholesky().map(|c| c.solve(&(tau - h)))
        } else {
            plant.forward_dynamics(&q, &qd, &tau)
        }
        .unwrap_or_else(JointVector::zeros);
        qd += qdd * servo.dt_s;
        q += qd * servo.dt_s;
    }
    Execution {
        ticks,
        max_error_rad: max_error,
        saturated_ticks,
        trip: None,
        end_state: (q, qd),
    }
}
