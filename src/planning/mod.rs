//! Planning: collision-free joint-space paths for the Pick and Place motions, fast.
//!
//! Job: given the arm, the cell and the pile as the sensor saw it, find a path from a start to a
//! goal configuration whose every edge is certified collision-free. Three parts, read in order:
//!
//! 1. [`model`]: the cell's collision model: the arm covered by spheres, the cell's boxes and the
//!    pile's height-map columns; clearance (a lower bound), free configurations, certified edges
//!    (conservative advancement) and discrete edge checks; [`pile_columns`]: the pile's columns and the
//!    max-pooled pyramid that finds the nearest one.
//!    [`axis_reach`]: how far each link reaches from each joint's axis at one configuration;
//!    [`certify`]: certified edges, conservative advancement with the motion bounded by how far
//!    the arm reaches from each joint's axis at each examined configuration.
//! 2. [`search`]: generic sampling-based search that knows nothing of robots: RRT, RRT-Connect
//!    and shortcutting over a configuration-space trait and an edge-validity trait, with the
//!    joint-box space of any dimension.
//! 3. [`planner`]: the cell's planner composed from them: direct connection, the workspace-guided
//!    escape from confined ends, RRT-Connect between them and shortcutting, all on certified
//!    edges (ours); plain RRT and RRT-Connect with discrete checks (the reference's baselines).
//!
//! Units: m, rad, s. Frames: joint space; the world for the cell and the escape's tool lines.

pub mod axis_reach;
pub mod certify;
pub mod model;
pub mod pile_columns;
pub mod planner;
pub mod search;

pub use axis_reach::AxisReach;
pub use model::{CollisionModel, Environment, Nearest, PileColumns, Probe, RobotSpheres, SELF_PAIRS, Sphere};
pub use planner::{Algorithm, CertifiedEdges, DiscreteEdges, Plan, PlanError, PlanOptions};
pub use search::{Budget, ConfigSpace, EdgeValidity, JointBox, PlanStats, Search};
