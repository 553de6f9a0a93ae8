//! binpick: a headless, simulation-in-the-loop digital twin of a robotic bin-picking cell
//! (an OMRON Viper s650 with a suction hand, a fixed overhead 3D sensor, a pick and a place tray).
//!
//! The modules follow one pick through the data flow:
//!
//! 1. [`config`]: the cell (scene) file and the workpiece files: strict parsing and validation.
//! 2. [`robot`]: the arm: URDF model, forward and inverse kinematics, dynamics with payload.
//! 3. [`physics`]: the rapier world: trays, piles of parts, the arm's bodies, the suction gripper.
//!
//! 4. [`sensor`]: the fixed overhead 3D sensor: ray-cast depth capture, exposure timing, recognition.
//! 5. [`grasp`]: the grasp selector: suction grasps from detections and the point cloud, ranked.
//! 6. [`planning`]: collision model (robot spheres, cell boxes, pile columns), certified edges, planner.
//! 7. [`trajectory`]: timed trajectories through via points, torques, the acceleration search.
//! 8. [`execution`]: the torque-limited 1 kHz joint servo on the arm's dynamics, protective stops.
//! 9. [`cycle`]: the cell cycle end to end: pipelined sensing and compute, Pick, Place, faults,
//!    refills, takt time.
//! 10. [`record`]: the run written to MCAP for Foxglove (Rerun to come; see README.md).
//! 11. [`report`]: run folders, written all-or-nothing with the resolved inputs beside the results;
//!     [`chart`]: the cycle's time chart (SVG); [`batch`]: takt-time tables over many runs.
//!
//! Units are SI inside the crate (m, rad, s, kg, N m); degrees appear only at the file and
//! command-line boundary. Frame names read `target_from_source` (e.g. `world_from_tool`).

pub mod batch;
pub mod bench;
pub mod chart;
pub mod config;
pub mod cycle;
pub mod execution;
pub mod geometry;
pub mod grasp;
pub mod physics;
pub mod planning;
pub mod record;
pub mod report;
pub mod rng;
pub mod robot;
pub mod sensor;
pub mod trajectory;
