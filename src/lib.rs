//! binpick: a headless, simulation-in-the-loop digital twin of a robotic bin-picking cell
//! (an OMRON Viper s650 with a suction hand, a fixed overhead 3D sensor, a pick and a place tray).
//!
//! The modules follow one pick through the data flow:
//!
//! 1. [`config`]: the cell (scene) file and the workpiece files: strict parsing and validation.
//! 2. [`part`]: the part model, one description of a workpiece's geometry for every stage: CAD
//!    import (STL, OBJ, KiCad VRML) and repair, and what is derived once from the mesh (mass
//!    properties, planar faces and their cup-fit regions, stable poses, symmetry); the built-in
//!    primitives and their tessellation;
//!    [`geometry`]: the cell's solid shapes (trays, table, obstacles as named boxes, the hand's
//!    cylinders) and the suction cup's force model, defined once for every stage below.
//! 3. [`robot`]: the arm: URDF model, forward and inverse kinematics, dynamics with payload.
//! 4. [`physics`]: the rapier world behind an API in metres: trays, piles of parts, the arm's
//!    bodies, the suction gripper, the health monitor, scene queries, event-driven stepping (no
//!    solver step where nothing can move).
//! 5. [`sensor`]: the fixed overhead 3D sensor: rasterized depth capture, exposure timing,
//!    recognition, the height map.
//! 6. [`grasp`]: the grasp selector: suction grasps from detections and the point cloud, ranked;
//!    [`pipeline`]: sense and grasp, from one capture to the grasp tried and its planning scene.
//! 7. [`planning`]: the collision model (robot spheres, cell boxes, pile columns), certified
//!    edges, generic sampling-based search, the cell's planner.
//! 8. [`trajectory`]: timed trajectories through via points, torques, the acceleration search,
//!    path correction, TOPP-RA, straight tool lines.
//! 9. [`servo`]: the torque-limited 1 kHz joint servo on the arm's dynamics, protective stops.
//! 10. [`cycle`]: the cell cycle end to end (sensing, motion generation, Pick, Place, faults,
//!     trays), its events and the observer interface through which a run is watched.
//! 11. [`recording`]: the run written to Rerun (`.rrd`) and MCAP files.
//! 12. [`results`]: the one results type's figures (a run's or many runs' [`cycle::Tally`]
//!     summarised), the takt table's columns, listed once for Markdown, CSV and JSON, and a
//!     batch's expected limits (`--expect`, JUnit XML);
//!     [`report`]: run folders, written all-or-nothing with the resolved inputs beside the
//!     results, the per-pick tables and a study's page (`report.html`); [`chart`]: the cycle's
//!     time chart (SVG).
//! 13. [`study`]: many cell runs, one table: the spec (variants x workpieces x seeds x picks x
//!     mode), the parallel runner, shards and their merge, its page; its front ends [`batch`]
//!     (the cell as given: the takt-time table) and [`sweep`] (variants of the cell and workpiece
//!     files);
//!     [`tune`], the third front end: an optimizer picks each round's variants, judged on test
//!     seeds it never evaluated.
//!
//! Beside the flow: [`mod@reference`] (the reference system's cases and tables), [`svg`] (the
//! drawing helpers every chart shares), [`stats`]
//! (statistics), [`rng`] (named seeded random streams), [`bench`](mod@bench) (the benchmarks).
//!
//! Units are SI inside the crate (m, rad, s, kg, N m); degrees appear only at the file and
//! command-line boundary. Frame names read `target_from_source` (e.g. `world_from_tool`).

pub mod batch;
pub mod bench;
pub mod chart;
pub mod config;
pub mod cycle;
pub mod geometry;
pub mod grasp;
pub mod part;
pub mod physics;
pub mod pipeline;
pub mod planning;
pub mod recording;
pub mod reference;
pub mod report;
pub mod results;
pub mod rng;
pub mod robot;
pub mod sensor;
pub mod servo;
pub mod stats;
pub mod study;
pub mod svg;
pub mod sweep;
pub mod trajectory;
pub mod tune;
