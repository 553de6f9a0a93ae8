//! The reference system's cases and tables, in one place for the benchmarks, the reports and the
//! tests (OMRON's fast motion planning for the Viper 650; `../shared/seeds/`).
//!
//! Job: rebuild the reference's planning cases (its Fig. 5: obstacles that block J1, J2 and J3)
//! and acceleration cases (its Fig. 11 / Table 4: J1 turns 180 deg between two open containers)
//! in the simulated cell, and hold the figures it reports (Tables 2, 4 and 5) with the
//! definitions they use, so every comparison with the reference reads them from here.
//!
//! Units: m, rad, s (ms where a table gives ms). Frames: world (z up, origin at the robot's
//! mounting face); the cases' obstacles stand on the table.

use nalgebra::{Isometry3, Vector3};

use crate::config::Scene;
use crate::geometry::NamedBox;
use crate::planning::{CollisionModel, Environment, RobotSpheres};
use crate::robot::{JointVector, RobotModel, tool_down_pose};

/// The reference's Table 5: takt per workpiece (s).
///
/// Definition (the reference's): the mean of 20 consecutive Pick-and-Place pairs of one
/// workpiece type, only the very first cycle's sensing and motion generation excluded.
pub const TABLE5_TAKT_S: [(&str, &str, f64); 6] = [
    ("A", "relay 2 x 3 x 1 cm", 2.9),
    ("B", "3 x 3 x 2 cm", 2.7),
    ("C", "strip 15 x 1 x 0.5 cm", 2.9),
    ("D", "1 x 1 x 1 cm", 2.9),
    ("E", "1 x 0.5 x 1 cm", 2.9),
    ("F", "1 x 1 x 0.5 cm", 3.0),
];

/// The reference system's takt for workpieces A..F (s) (its Table 5), `None` for others.
pub fn reference_takt(name: &str) -> Option<f64> {
    TABLE5_TAKT_S.iter().find(|(w, _, _)| *w == name).map(|(_, _, t)| *t)
}

/// One row of the reference's Table 2 (planning on its three Fig. 5 cases, 100 trials each, on
/// an i5-4310U at 2.0 GHz).
#[derive(Debug, Clone, Copy)]
pub struct PlannerFigures {
    /// Planner.
    pub name: &'static str,
    /// Mean planning time (ms).
    pub mean_ms: f64,
    /// Maximum planning time (ms).
    pub max_ms: f64,
    /// Success rate [%].
    pub success_pct: f64,
}

/// The reference's Table 2: its developed method and the baselines on the Fig. 5 cases.
pub const TABLE2_PLANNING: [PlannerFigures; 5] = [
    PlannerFigures {
        name: "developed",
        mean_ms: 28.9,
        max_ms: 90.4,
        success_pct: 100.0,
    },
    PlannerFigures {
        name: "RRT-Connect",
        mean_ms: 761.0,
        max_ms: 1629.0,
        success_pct: 99.0,
    },
    PlannerFigures {
        name: "RRT",
        mean_ms: 826.0,
        max_ms: 2086.0,
        success_pct: 97.0,
    },
    PlannerFigures {
        name: "TRRT",
        mean_ms: 892.0,
        max_ms: 2047.0,
        success_pct: 94.0,
    },
    PlannerFigures {
        name: "BIT*",
        mean_ms: 696.0,
        max_ms: 2115.0,
        success_pct: 100.0,
    },
];

/// One planning benchmark case: an environment and a start and goal.
#[derive(Debug, Clone)]
pub struct PlannerCase {
    /// Name.
    pub name: String,
    /// Collision model (robot spheres and environment).
    pub model: CollisionModel,
    /// Start configuration.
    pub start: JointVector,
    /// Goal configuration.
    pub goal: JointVector,
}

/// The cell's table as the only obstacle (the reference's cases stand on an empty table).
fn table_only(scene: &Scene) -> Environment {
    Environment {
        boxes: vec![crate::geometry::table_box(scene)],
        pile: None,
    }
}

/// An axis-aligned box centred at `c` of full size `size` (m).
fn bx(name: &str, c: [f64; 3], size: [f64; 3]) -> NamedBox {
    NamedBox {
        name: name.into(),
        world_from_box: Isometry3::translation(c[0], c[1], c[2]),
        half_m: Vector3::from(size) / 2.0,
    }
}

/// An open container standing on z = 0: a 1 cm floor and four 1 cm walls around (x, y), inner
/// size `inner` square, wall height `h` (m).
fn container(name: &str, x: f64, y: f64, inner: f64, h: f64) -> Vec<NamedBox> {
    let t = 0.01;
    let o = inner / 2.0 + t / 2.0;
    vec![
        bx(
            &format!("{name} floor"),
            [x, y, t / 2.0],
            [inner + 2.0 * t, inner + 2.0 * t, t],
        ),
        bx(&format!("{name} wall +x"), [x + o, y, h / 2.0], [t, inner + 2.0 * t, h]),
        bx(&format!("{name} wall -x"), [x - o, y, h / 2.0], [t, inner + 2.0 * t, h]),
        bx(&format!("{name} wall +y"), [x, y + o, h / 2.0], [inner, t, h]),
        bx(&format!("{name} wall -y"), [x, y - o, h / 2.0], [inner, t, h]),
    ]
}

/// The tool pointing straight down at `p` (m), solved nearest the cell's home.
fn tool_down_ik(robot: &RobotModel, scene: &Scene, p: [f64; 3]) -> Result<JointVector, String> {
    let home = JointVector::from(scene.robot.home_rad());
    robot
        .ik_tool_nearest(&tool_down_pose(Vector3::from(p), 0.0), &home)
        .map(|s| s.q)
        .map_err(|e| format!("case pose {p:?}: {e}"))
}

/// The reference system's three planning cases (its Fig. 5), rebuilt from the text: obstacles
/// between start and goal that block the motion of J1 (a wall between two work points), of J2
/// (a bar the arm must pass over to reach beyond it), and of J3 (the hand inside one container
/// going into another).
pub fn fig5_cases(scene: &Scene, robot: &RobotModel) -> Result<Vec<PlannerCase>, String> {
    let spheres = RobotSpheres::new(robot, scene, None);
    let ik = |p: [f64; 3]| tool_down_ik(robot, scene, p);
    let mut cases = Vec::new();
    let mut env = table_only(scene);
    env.boxes.push(bx("wall", [0.52, 0.0, 0.20], [0.24, 0.03, 0.40]));
    cases.push(PlannerCase {
        name: "J1 blocked: wall between two work points".into(),
        model: CollisionModel::new(robot, spheres.clone(), env),
        start: ik([0.45, 0.28, 0.06])?,
        goal: ik([0.45, -0.28, 0.06])?,
    });
    let mut env = table_only(scene);
    env.boxes.push(bx("bar", [0.45, 0.0, 0.25], [0.04, 0.70, 0.04]));
    cases.push(PlannerCase {
        name: "J2 blocked: reach over a bar".into(),
        model: CollisionModel::new(robot, spheres.clone(), env),
        start: ik([0.32, 0.0, 0.06])?,
        goal: ik([0.60, 0.0, 0.06])?,
    });
    let mut env = table_only(scene);
    env.boxes.extend(container("container 1", 0.40, 0.26, 0.12, 0.12));
    env.boxes.extend(container("container 2", 0.40, -0.26, 0.12, 0.12));
    cases.push(PlannerCase {
        name: "J3 blocked: out of one container into another".into(),
        model: CollisionModel::new(robot, spheres, env),
        start: ik([0.40, 0.26, 0.03])?,
        goal: ik([0.40, -0.26, 0.03])?,
    });
    Ok(cases)
}

/// The part held in the acceleration cases: 30 g, a 3 x 3 x 2 cm box 1 cm beyond the tool frame.
pub const ACCEL_PART_KG: f64 = 0.03;

/// One of the reference's acceleration cases with the figures its Table 4 gives for it.
#[derive(Debug, Clone)]
pub struct AccelCase {
    /// Case name (A->a ... E->e).
    pub name: &'static str,
    /// Collision model: the hand holding the part, the table and the two containers.
    pub model: CollisionModel,
    /// Start: the tool 5 cm above the first container's floor.
    pub start: JointVector,
    /// Goal: the same above the second container, J1 turned 180 deg.
    pub goal: JointVector,
    /// The reference's Table 4: motion time improvement over default parameters [%].
    pub table4_improvement_pct: f64,
    /// The reference's Table 4: maximum compute time, planning included (ms).
    pub table4_compute_ms: f64,
}

/// The reference system's five acceleration cases (its Fig. 11 / Table 4): the hand leaves one
/// open container and enters another while J1 turns 180 deg, at five reaches and heights, with
/// the default hand holding a 30 g part.
pub fn accel_cases(scene: &Scene, robot: &RobotModel) -> Result<Vec<AccelCase>, String> {
    // (name, reach [m], container height above the table [m], Table 4 improvement [%], compute [ms])
    let setups = [
        ("A->a", 0.40, 0.00, 24.7, 95.1),
        ("B->b", 0.50, 0.00, 19.4, 97.1),
        ("C->c", 0.35, 0.10, 28.1, 96.5),
        ("D->d", 0.45, 0.15, 28.3, 85.3),
        ("E->e", 0.55, 0.05, 23.3, 90.0),
    ];
    let held = Some((Isometry3::translation(0.0, 0.0, 0.01), Vector3::new(0.015, 0.015, 0.01)));
    let mut cases = Vec::new();
    for (name, reach, z, improvement, compute) in setups {
        let mut env = table_only(scene);
        for y in [reach, -reach] {
            env.boxes
                .extend(container("container", 0.0, y, 0.12, 0.10).into_iter().map(|mut b| {
                    b.world_from_box.translation.vector.z += z;
                    b
                }));
        }
        let model = CollisionModel::new(robot, RobotSpheres::new(robot, scene, held), env);
        let ik = |y: f64| tool_down_ik(robot, scene, [0.0, y, z + 0.05]).map_err(|e| format!("{name}: {e}"));
        cases.push(AccelCase {
            name,
            model,
            start: ik(reach)?,
            goal: ik(-reach)?,
            table4_improvement_pct: improvement,
            table4_compute_ms: compute,
        });
    }
    Ok(cases)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table5_covers_the_six_workpieces() {
        assert_eq!(reference_takt("B"), Some(2.7));
        assert_eq!(reference_takt("F"), Some(3.0));
        assert_eq!(reference_takt("capacitor-radial"), None);
        assert!(TABLE5_TAKT_S.iter().all(|(_, _, t)| (2.7..=3.0).contains(t)));
    }
}
