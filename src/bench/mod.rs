//! Benchmarks run by `binpick bench ...`: our code beside a baseline or peer doing the same work,
//! in the same run, on the embedded default cell.
//!
//! Job: time each stage's hot work over several runs and report medians (with minima and
//! maxima); inputs come from seeded streams, so every run times the same work. One file per
//! stage: [`robot`], [`physics`], [`sensor`], [`planner`], [`accel`]; the reference's cases and
//! figures come from [`crate::reference`].
//!
//! Units: as each file says (ns per call, ms per plan, s of motion).

pub mod accel;
pub mod physics;
pub mod planner;
pub mod robot;
pub mod sensor;

pub use accel::{AccelRow, accel_bench};
pub use physics::{MeshPileTiming, PhysicsBench, PileTiming, physics_bench};
pub use planner::{PlannerRow, binpicking_queries, planner_bench};
pub use robot::{RobotBench, Timing, numerical_ik, robot_bench, time_per_call};
pub use sensor::{SenseBench, SenseTiming, sense_bench};
