//! `binpick tune`: the cell's settings chosen by an optimizer, the third front end of the study
//! pipeline. Each round's candidates are the variants of one study ([`crate::study`]: they run
//! in parallel through the one runner); the figure reported is measured afterwards on test seeds
//! the optimizer never evaluated, beside the untuned cell on the same seeds.
//!
//! Job: parse the varied keys (`--vary KEY=LO:HI`: a continuous key, or an integer key when the
//! resolved file holds an integer there, rounded to whole numbers), drive the optimizer round by
//! round over an [`Evaluator`] (the cell's is [`cell`]; the tests' is a formula), keep every
//! evaluation with its feasibility, and pick the best: the lowest training takt among the
//! evaluations that meet every constraint ([`best`] reads the log, never the optimizer's own
//! state, so a candidate that violates a constraint is never returned whatever the optimizer
//! believed). [`journal`] keeps the finished evaluations for resuming; [`output`] writes
//! `tune.md`, `tune.json` and the convergence chart `tune.svg`.
//!
//! The optimizer: argmin's particle swarm (`argmin` 0.11, `ParticleSwarm`), chosen over
//! - egobox (Bayesian optimisation): the better sampler for a tiny budget, but it pulls ndarray,
//!   linfa and a linear-algebra stack (optionally BLAS/LAPACK): minutes more of a 2-core cold
//!   build for one command;
//! - the `cmaes` crate: fine for continuous keys, but it brings its own nalgebra and rand
//!   versions and statistics crates, and its generation loop owns the objective's call;
//! - argmin's other derivative-free solvers (Nelder-Mead, simulated annealing): one candidate at
//!   a time, so nothing to run in parallel.
//!
//! argmin with only its `rand` feature adds three small crates to the build (argmin, argmin-math,
//! rand_xoshiro; the rand 0.9 and num-complex they use were already built for other
//! dependencies), no BLAS. The swarm is
//! population-based, so a round (its `population` particles) is one study run in parallel; it
//! takes box bounds natively (positions are clamped into them) and it needs no gradient, so a
//! noisy objective and rounded integer keys are fine. Its random numbers come from
//! `rand_xoshiro` seeded by a draw from the run's named ChaCha stream `tune-optimizer`
//! ([`crate::rng`]): the same seed asks for the same candidates, bit for bit.
//!
//! Integer keys: the swarm moves over `[lo - 0.5, hi + 0.5)` and the candidate is rounded, so each
//! whole number gets an equal share. Continuous keys are rounded to 5 significant digits of the
//! range (clean numbers in the files, exact keys for the journal). A candidate the cell file's
//! own validation refuses is not run; the optimizer is told it is infeasible (a large cost).
//! Constraint violations are penalised by how far they miss ([`INFEASIBLE_COST`]), so the swarm
//! steers toward the feasible region.
//!
//! The budget counts candidates asked for; the last round is cut short when the budget ends in
//! it (its remaining particles are never run). Each finished evaluation goes to the journal and a
//! re-run resumes from it (the same seed asks for the same candidates, whose figures the journal
//! already has). Rounds beyond the first depend on the figures of the ones before, so a round is
//! split across machines rather than the rounds: shards ([`cell::Cell::shard`]) each run their
//! share of every round and read the rest from each other's journals in a shared folder; every
//! shard's optimizer sees the same figures and asks for the same next round.
//!
//! The objective ([`Objective`], `--objective`): the sustained takt by default, every interval
//! of runs long enough to span several pile cycles (`--picks` defaults to
//! [`crate::results::SUSTAINED_PICKS`]): what a line keeps up is what a cell engineer buys, and
//! the keys that act when the pile runs low (agitation, refills, a hopper's dose threshold) have
//! no effect at all on a full pile's first 21 picks, so a 20-pick objective could not tell their
//! values apart. `--objective first20` optimizes the reference's 20-pick figure instead (each
//! run's first 21 picks). Both figures are kept for every evaluation.
//!
//! Units: the files' own for the keys (their names carry them); s and counts in the figures.

pub mod cell;
pub mod journal;
pub mod output;

use std::cell::RefCell;

use argmin::core::{CostFunction, Error as ArgminError, PopulationState, Problem, SendAlias, Solver, State, SyncAlias};
use argmin::solver::particleswarm::ParticleSwarm;
use rand::RngExt;
use rand_xoshiro::Xoshiro256PlusPlus;
use rand_xoshiro::rand_core::SeedableRng;
use serde::{Deserialize, Serialize};

use crate::cycle::Tally;
use crate::results::Summary;
use crate::study::StudyError;
use crate::sweep::{Segment, Target};

/// The cost the optimizer is given for a candidate that was run but violates a constraint, times
/// one plus how far it is from feasible ([`Constraints::violation`]), plus its takt: above any
/// feasible takt; among infeasible candidates the swarm prefers the nearer, then the faster.
pub const INFEASIBLE_COST: f64 = 1.0e3;
/// The cost of a candidate the cell file's validation refuses (never run).
pub const REFUSED_COST: f64 = 1.0e6;

fn input(m: impl Into<String>) -> StudyError {
    StudyError::Input(m.into())
}

/// One varied key and its range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dim {
    /// The key as written (`gripper.cup_diameter_m`, `workpiece.grasp.face_margin_m`).
    pub key: String,
    /// Lowest value.
    pub lo: f64,
    /// Highest value.
    pub hi: f64,
    /// Whether the key takes whole numbers (decided by the resolved file's value, see
    /// [`cell::check_keys`]).
    pub integer: bool,
}

impl Dim {
    /// The file the key goes into and its path there.
    pub fn target(&self) -> (Target, Vec<Segment>) {
        crate::sweep::parse_key(&self.key).expect("checked when parsed")
    }

    /// Decimals a continuous value is written with: 5 significant digits of the range.
    fn decimals(&self) -> usize {
        let span = self.hi - self.lo;
        (5 - span.log10().floor() as i32).clamp(0, 15) as usize
    }

    /// The optimizer's box for the key.
    fn bounds(&self) -> (f64, f64) {
        if self.integer {
            (self.lo - 0.5, self.hi + 0.5 - 1e-9)
        } else {
            (self.lo, self.hi)
        }
    }

    /// An optimizer position snapped to a value the key takes (within the range).
    pub fn snap(&self, x: f64) -> f64 {
        if self.integer {
            x.round().clamp(self.lo, self.hi)
        } else {
            let d = self.decimals();
            format!("{:.d$}", x.clamp(self.lo, self.hi)).parse().unwrap_or(self.lo)
        }
    }

    /// A snapped value as the file's TOML value.
    pub fn value(&self, x: f64) -> toml::Value {
        if self.integer {
            toml::Value::Integer(x as i64)
        } else {
            toml::Value::Float(x)
        }
    }
}

/// Parses one `--vary KEY=LO:HI`. Whether the key takes integers is for the resolved file to say
/// ([`cell::check_keys`]); here both bounds must be finite numbers, LO below HI.
pub fn parse_vary(text: &str) -> Result<Dim, StudyError> {
    let (key, range) = text
        .split_once('=')
        .ok_or_else(|| input(format!("--vary: expected KEY=LO:HI, got {text:?}")))?;
    let key = key.trim();
    crate::sweep::parse_key(key).map_err(|m| input(format!("--vary: {m}")))?;
    let bad = |why: &str| input(format!("--vary {key}: {range:?} {why}"));
    let (lo, hi) = range.split_once(':').ok_or_else(|| bad("is not a range LO:HI"))?;
    let num = |t: &str| t.trim().parse::<f64>().ok().filter(|v| v.is_finite());
    let (Some(lo), Some(hi)) = (num(lo), num(hi)) else {
        return Err(bad("needs two finite numbers, LO:HI"));
    };
    if lo >= hi {
        return Err(bad("is empty or reversed: LO must be below HI"));
    }
    Ok(Dim {
        key: key.to_string(),
        lo,
        hi,
        integer: false,
    })
}

/// Parses every `--vary`: at least one, no key twice, not a workpiece's name.
pub fn parse_varies(texts: &[String]) -> Result<Vec<Dim>, StudyError> {
    if texts.is_empty() {
        return Err(input("tune: give at least one --vary KEY=LO:HI"));
    }
    let mut dims: Vec<Dim> = Vec::new();
    for t in texts {
        let d = parse_vary(t)?;
        if d.target() == (Target::Workpiece, vec![Segment::Key("name".into())]) {
            return Err(input(format!("--vary {}: a workpiece's name is not a number", d.key)));
        }
        if dims.iter().any(|x| x.target() == d.target()) {
            return Err(input(format!("--vary {}: the same key is varied twice", d.key)));
        }
        dims.push(d);
    }
    Ok(dims)
}

/// What a best must meet, each a command-line key.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Constraints {
    /// Lowest success rate (placed within the place tray's tolerance / attempts), 0 to 1.
    pub min_success: f64,
    /// Most collisions over the training runs.
    pub max_collisions: usize,
    /// Most protective stops.
    pub max_stops: usize,
    /// Most parts lost.
    pub max_parts_lost: usize,
}

/// The one of `all` whose name (`name`) is `text`: how a command-line option's text becomes the
/// choice it names.
fn named<T: Copy>(all: &[T], name: fn(T) -> &'static str, text: &str) -> Option<T> {
    all.iter().copied().find(|o| name(*o) == text)
}

/// Which takt the optimizer minimises (see the module's header).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Objective {
    /// Every interval of the runs (the sustained takt when they span several piles).
    #[default]
    Sustained,
    /// The reference's 20-pick figure: the intervals of each run's first 21 picks.
    First20,
}

impl Objective {
    /// Its name on the command line and in the files.
    pub fn text(self) -> &'static str {
        match self {
            Objective::Sustained => "sustained",
            Objective::First20 => "first20",
        }
    }

    /// The objective named `text`, if it is one.
    pub fn parse(text: &str) -> Option<Objective> {
        named(&[Objective::Sustained, Objective::First20], Objective::text, text)
    }
}

/// A candidate's figures over its runs (the training seeds, or the test seeds): the takt table's
/// figures of the runs merged, as `batch` over the same seeds reports them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Figures {
    /// The objective's takt (s): the mean of the intervals it spans; none if no interval.
    pub takt_s: Option<f64>,
    /// Intervals the takt is the mean of.
    pub takt_count: usize,
    /// Every interval of the runs (s): the sustained takt.
    #[serde(default)]
    pub sustained_takt_s: Option<f64>,
    /// The intervals of each run's first 21 picks (s): the reference's 20-pick takt.
    #[serde(default)]
    pub first20_takt_s: Option<f64>,
    /// placed within the place tray's tolerance / attempts; none without attempts.
    pub success_rate: Option<f64>,
    /// Parts placed.
    pub placed: usize,
    /// Attempts.
    pub attempts: usize,
    /// Collisions.
    pub collisions: usize,
    /// Protective stops.
    pub protective_stops: usize,
    /// Parts lost.
    pub parts_lost: usize,
    /// Drops (not a constraint: a drop back into the tray is re-picked).
    pub drops: usize,
    /// Runs ended by a physics fault (never allowed: such a run's picks stop short, and its
    /// takt is that of fewer picks).
    #[serde(default)]
    pub physics_faults: usize,
    /// Runs merged.
    pub runs: usize,
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl Figures {
    /// The figures of runs merged into one tally, the takt by `objective`.
    pub fn of(tally: &Tally, objective: Objective) -> Figures {
        let s = Summary::of(tally);
        let f = &tally.faults;
        let takt = match objective {
            Objective::Sustained => s.takt,
            Objective::First20 => s.takt_first,
        };
        Figures {
            takt_s: finite(takt.mean_s),
            takt_count: takt.count,
            sustained_takt_s: finite(s.takt.mean_s),
            first20_takt_s: finite(s.takt_first.mean_s),
            success_rate: finite(s.success_rate),
            placed: tally.placed,
            attempts: tally.attempts,
            collisions: f.collisions,
            protective_stops: f.protective_stops,
            parts_lost: f.parts_lost,
            drops: f.drops,
            physics_faults: tally.physics_faults.len(),
            runs: tally.runs,
        }
    }
}

impl Constraints {
    /// Each constraint `f` violates, as text (empty: feasible). No takt measured is a violation.
    pub fn violations(&self, f: &Figures) -> Vec<String> {
        let mut v = Vec::new();
        if f.takt_s.is_none() {
            v.push("no takt measured".to_string());
        }
        match f.success_rate {
            Some(s) if s >= self.min_success => {}
            s => v.push(format!(
                "success {} below {:.1} %",
                s.map_or("-".into(), |s| format!("{:.1} %", 100.0 * s)),
                100.0 * self.min_success
            )),
        }
        let mut over = |n: usize, max: usize, what: &str| {
            if n > max {
                v.push(format!("{n} {what} (at most {max})"));
            }
        };
        over(f.collisions, self.max_collisions, "collisions");
        over(f.protective_stops, self.max_stops, "protective stops");
        over(f.parts_lost, self.max_parts_lost, "parts lost");
        over(f.physics_faults, 0, "runs ended by a physics fault");
        v
    }

    /// How far `f` is from feasible: the success rate's shortfall (0 to 1) plus each count over
    /// its limit, plus 1 without a takt (0: feasible). It scales the penalty, so among
    /// infeasible candidates the swarm is drawn toward the feasible region.
    pub fn violation(&self, f: &Figures) -> f64 {
        let over = |n: usize, max: usize| n.saturating_sub(max) as f64;
        let success = f.success_rate.map_or(1.0, |s| (self.min_success - s).max(0.0));
        success
            + over(f.collisions, self.max_collisions)
            + over(f.protective_stops, self.max_stops)
            + over(f.parts_lost, self.max_parts_lost)
            + over(f.physics_faults, 0)
            + if f.takt_s.is_none() { 1.0 } else { 0.0 }
    }
}

/// What became of a candidate.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Run on the training seeds.
    Measured(Figures),
    /// Refused by the cell file's validation (the message): not run.
    Refused(String),
}

/// One candidate the optimizer asked for, and what it came to.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// 0-based, in the order asked.
    pub index: usize,
    /// 0-based round (the swarm's initial round is 0).
    pub round: usize,
    /// The values, snapped, in `--vary` order.
    pub values: Vec<f64>,
    /// Its figures, or why it was not run.
    pub outcome: Outcome,
    /// The constraints it violates (empty: feasible).
    pub violations: Vec<String>,
    /// The cost the optimizer was given.
    pub cost: f64,
}

impl Evaluation {
    /// Run and meets every constraint.
    pub fn feasible(&self) -> bool {
        matches!(self.outcome, Outcome::Measured(_)) && self.violations.is_empty()
    }

    /// Its training figures, if it was run.
    pub fn figures(&self) -> Option<&Figures> {
        match &self.outcome {
            Outcome::Measured(f) => Some(f),
            Outcome::Refused(_) => None,
        }
    }
}

/// Runs the candidates of one round.
pub trait Evaluator {
    /// The outcomes of `candidates` (snapped values, `--vary` order), in order.
    fn evaluate(&mut self, round: usize, candidates: &[Vec<f64>]) -> Result<Vec<Outcome>, StudyError>;
}

/// Who asks for the candidates (`--optimizer`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Optimizer {
    /// argmin's particle swarm (the module's header).
    #[default]
    Swarm,
    /// The baseline a cell engineer would lay out by hand: a full grid over the keys with the
    /// same number of points on each ([`grid`]), as many as the budget allows, run in rounds of
    /// the population like the swarm's. What `tune` is judged against.
    Grid,
}

impl Optimizer {
    /// Its name on the command line and in the files.
    pub fn text(self) -> &'static str {
        match self {
            Optimizer::Swarm => "swarm",
            Optimizer::Grid => "grid",
        }
    }

    /// The optimizer named `text`, if it is one.
    pub fn parse(text: &str) -> Option<Optimizer> {
        named(&[Optimizer::Swarm, Optimizer::Grid], Optimizer::text, text)
    }
}

/// The grid [`Optimizer::Grid`] runs: `n` evenly spaced values on each key, both ends included
/// (one key's only value is its middle), with `n` the largest whole number whose power of the
/// key count stays within `budget`; an integer key with fewer than `n` whole values takes each
/// of them once, and the points it frees are not spent elsewhere. Values are snapped as the
/// swarm's are; the first key varies slowest.
pub fn grid(dims: &[Dim], budget: usize) -> Vec<Vec<f64>> {
    let k = dims.len().max(1) as u32;
    let mut n = 1usize;
    while (n + 1).checked_pow(k).is_some_and(|p| p <= budget) {
        n += 1;
    }
    let axes: Vec<Vec<f64>> = dims
        .iter()
        .map(|d| {
            let count = if d.integer {
                n.min((d.hi - d.lo).round() as usize + 1)
            } else {
                n
            };
            let mut values: Vec<f64> = (0..count)
                .map(|i| {
                    let x = if count == 1 {
                        0.5 * (d.lo + d.hi)
                    } else {
                        d.lo + (d.hi - d.lo) * i as f64 / (count - 1) as f64
                    };
                    d.snap(x)
                })
                .collect();
            values.dedup();
            values
        })
        .collect();
    let mut points: Vec<Vec<f64>> = vec![Vec::new()];
    for axis in &axes {
        points = points
            .into_iter()
            .flat_map(|p| {
                axis.iter().map(move |x| {
                    let mut q = p.clone();
                    q.push(*x);
                    q
                })
            })
            .collect();
    }
    points
}

/// How the optimizer runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    /// Candidates asked for, in all.
    pub budget: usize,
    /// Particles of the swarm: candidates per round.
    pub population: usize,
    /// Who asks for the candidates.
    #[serde(default)]
    pub optimizer: Optimizer,
    /// The run's seed (the optimizer's random numbers come from its `tune-optimizer` stream).
    pub seed: u64,
    /// What a best must meet.
    pub constraints: Constraints,
}

/// The optimizer's view of the evaluator: a round's positions snapped, run, logged, costed.
struct Cost<'a> {
    dims: &'a [Dim],
    settings: &'a Settings,
    state: RefCell<CostState<'a>>,
}

struct CostState<'a> {
    evaluator: &'a mut dyn Evaluator,
    log: Vec<Evaluation>,
    round: usize,
    /// The evaluator's error, if it failed.
    failure: Option<StudyError>,
}

impl<'a> Cost<'a> {
    /// A cost over `dims` under `settings`, with an empty log.
    fn new(dims: &'a [Dim], settings: &'a Settings, evaluator: &'a mut dyn Evaluator) -> Self {
        Cost {
            dims,
            settings,
            state: RefCell::new(CostState {
                evaluator,
                log: Vec::new(),
                round: 0,
                failure: None,
            }),
        }
    }

    /// The evaluations logged, or the evaluator's error if it failed.
    fn into_log(self) -> Result<Vec<Evaluation>, StudyError> {
        let st = self.state.into_inner();
        match st.failure {
            Some(e) => Err(e),
            None => Ok(st.log),
        }
    }

    fn round(&self, positions: &[Vec<f64>]) -> Result<Vec<f64>, ArgminError> {
        let mut st = self.state.borrow_mut();
        let left = self.settings.budget.saturating_sub(st.log.len());
        let take = positions.len().min(left);
        let candidates: Vec<Vec<f64>> = positions[..take]
            .iter()
            .map(|p| self.dims.iter().zip(p).map(|(d, x)| d.snap(*x)).collect())
            .collect();
        let round = st.round;
        let outcomes = match st.evaluator.evaluate(round, &candidates) {
            Ok(o) => o,
            Err(e) => {
                st.failure = Some(e);
                return Err(ArgminError::msg("the evaluator failed"));
            }
        };
        let mut costs = Vec::with_capacity(positions.len());
        for (values, outcome) in candidates.into_iter().zip(outcomes) {
            let (violations, cost) = match &outcome {
                Outcome::Measured(f) => {
                    let v = self.settings.constraints.violations(f);
                    let takt = f.takt_s.unwrap_or(0.0);
                    let c = &self.settings.constraints;
                    let cost = if v.is_empty() {
                        takt
                    } else {
                        INFEASIBLE_COST * (1.0 + c.violation(f)) + takt
                    };
                    (v, cost)
                }
                Outcome::Refused(m) => (vec![format!("refused: {m}")], REFUSED_COST),
            };
            costs.push(cost);
            let index = st.log.len();
            st.log.push(Evaluation {
                index,
                round,
                values,
                outcome,
                violations,
                cost,
            });
        }
        st.round += 1;
        if take < positions.len() {
            // The budget ended within the round: the rest are never run.
            return Err(ArgminError::msg("budget spent"));
        }
        Ok(costs)
    }
}

impl CostFunction for Cost<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, p: &Vec<f64>) -> Result<f64, ArgminError> {
        Ok(self.round(std::slice::from_ref(p))?[0])
    }

    fn bulk_cost<P>(&self, params: &[P]) -> Result<Vec<f64>, ArgminError>
    where
        P: std::borrow::Borrow<Vec<f64>> + SyncAlias,
        f64: SendAlias,
        Self: SyncAlias,
    {
        let positions: Vec<Vec<f64>> = params.iter().map(|p| p.borrow().clone()).collect();
        self.round(&positions)
    }
}

/// Runs the optimizer over `dims` until `settings.budget` candidates were asked for; returns
/// every evaluation in the order asked. The optimizer's own failures end the search early with
/// what it has; the evaluator's are returned.
pub fn optimize(
    dims: &[Dim],
    settings: &Settings,
    evaluator: &mut dyn Evaluator,
) -> Result<Vec<Evaluation>, StudyError> {
    if dims.is_empty() || settings.budget == 0 || settings.population == 0 {
        return Err(input("tune: needs a key, a budget and a population of at least 1"));
    }
    if settings.optimizer == Optimizer::Grid {
        return run_grid(dims, settings, evaluator);
    }
    let seed: u64 = crate::rng::stream(settings.seed, "tune-optimizer").random();
    let (lo, hi): (Vec<f64>, Vec<f64>) = dims.iter().map(Dim::bounds).unzip();
    let mut swarm =
        ParticleSwarm::new((lo, hi), settings.population).with_rng_generator(Xoshiro256PlusPlus::seed_from_u64(seed));
    let mut problem = Problem::new(Cost::new(dims, settings, evaluator));
    let mut state = match swarm.init(&mut problem, PopulationState::new()) {
        Ok((s, _)) => Some(s),
        Err(_) => None,
    };
    let spent = |p: &Problem<Cost<'_>>| {
        p.problem
            .as_ref()
            .is_none_or(|c| c.state.borrow().log.len() >= settings.budget)
    };
    while let Some(s) = state.take() {
        if spent(&problem) {
            break;
        }
        state = swarm.next_iter(&mut problem, s).ok().map(|(s, _)| s);
    }
    problem
        .take_problem()
        .ok_or_else(|| StudyError::Run("the optimizer lost its objective".into()))?
        .into_log()
}

/// [`Optimizer::Grid`]: the [`grid`]'s points in rounds of the population, through the same
/// costing and log as the swarm's rounds.
fn run_grid(dims: &[Dim], settings: &Settings, evaluator: &mut dyn Evaluator) -> Result<Vec<Evaluation>, StudyError> {
    let cost = Cost::new(dims, settings, evaluator);
    for chunk in grid(dims, settings.budget).chunks(settings.population) {
        if cost.round(chunk).is_err() {
            break;
        }
    }
    cost.into_log()
}

/// The best evaluation: the lowest training takt among the feasible ones (the first of equals);
/// none if none is feasible.
pub fn best(evaluations: &[Evaluation]) -> Option<&Evaluation> {
    evaluations
        .iter()
        .filter(|e| e.feasible())
        .filter_map(|e| e.figures().and_then(|f| f.takt_s).map(|t| (t, e)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, e)| e)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic cell: takt = (x - 0.011)^2 * 1e4 + (n - 5)^2 * 0.05 + 1, success 1, no faults;
    /// `unsafe_below` gives candidates with x below it a collision.
    struct Quadratic {
        unsafe_below: f64,
        rounds: Vec<usize>,
    }

    impl Evaluator for Quadratic {
        fn evaluate(&mut self, round: usize, c: &[Vec<f64>]) -> Result<Vec<Outcome>, StudyError> {
            self.rounds.push(round);
            Ok(c.iter()
                .map(|v| {
                    let (x, n) = (v[0], v[1]);
                    let takt = (x - 0.011).powi(2) * 1e4 + (n - 5.0).powi(2) * 0.05 + 1.0;
                    Outcome::Measured(Figures {
                        takt_s: Some(takt),
                        takt_count: 20,
                        sustained_takt_s: Some(takt),
                        first20_takt_s: Some(takt),
                        success_rate: Some(1.0),
                        placed: 21,
                        attempts: 21,
                        collisions: usize::from(x < self.unsafe_below),
                        protective_stops: 0,
                        parts_lost: 0,
                        physics_faults: 0,
                        drops: 0,
                        runs: 1,
                    })
                })
                .collect())
        }
    }

    fn dims() -> Vec<Dim> {
        let mut d = parse_varies(&[
            "gripper.cup_diameter_m=0.004:0.02".into(),
            "agitation.max_tries=1:8".into(),
        ])
        .unwrap();
        d[1].integer = true;
        d
    }

    fn settings(budget: usize, max_collisions: usize) -> Settings {
        Settings {
            budget,
            population: 10,
            optimizer: Optimizer::Swarm,
            seed: 1,
            constraints: Constraints {
                min_success: 0.95,
                max_collisions,
                max_stops: 0,
                max_parts_lost: 0,
            },
        }
    }

    #[test]
    fn the_swarm_finds_a_shifted_quadratics_optimum_in_a_continuous_and_an_integer_key() {
        let mut q = Quadratic {
            unsafe_below: f64::NEG_INFINITY,
            rounds: Vec::new(),
        };
        let evals = optimize(&dims(), &settings(200, 0), &mut q).unwrap();
        assert_eq!(evals.len(), 200);
        // Rounds of the population: 20 rounds of 10 candidates, in order.
        assert_eq!(q.rounds, (0..20).collect::<Vec<_>>());
        let b = best(&evals).unwrap();
        assert!((b.values[0] - 0.011).abs() < 5e-4, "{:?}", b.values);
        assert_eq!(b.values[1], 5.0, "{:?}", b.values);
        // Every integer candidate is whole and in range; every continuous one in range.
        assert!(
            evals
                .iter()
                .all(|e| e.values[1].fract() == 0.0 && (1.0..=8.0).contains(&e.values[1]))
        );
        assert!(evals.iter().all(|e| (0.004..=0.02).contains(&e.values[0])));
        // Negative control: the first round alone (random sampling) is not this close.
        let first = best(&evals[..10]).unwrap();
        assert!(
            (first.values[0] - 0.011).abs() >= 5e-4 || first.values[1] != 5.0,
            "{:?}",
            first.values
        );
    }

    #[test]
    fn a_constraint_violating_candidate_is_never_the_best() {
        // Collisions below 0.013: the unconstrained optimum (0.011) is unsafe.
        let run = |max_collisions| {
            let mut q = Quadratic {
                unsafe_below: 0.013,
                rounds: Vec::new(),
            };
            let evals = optimize(&dims(), &settings(120, max_collisions), &mut q).unwrap();
            best(&evals).cloned().unwrap()
        };
        let b = run(0);
        assert!(b.values[0] >= 0.013 && b.feasible(), "{:?}", b.values);
        // Negative control: with the constraint off, the best is a colliding candidate.
        let free = run(usize::MAX);
        assert!(free.values[0] < 0.013, "{:?}", free.values);
        assert_eq!(free.figures().unwrap().collisions, 1);
    }

    #[test]
    fn the_penalty_grows_with_how_far_a_candidate_misses() {
        let c = settings(1, 0).constraints;
        let f = |success: f64, collisions: usize| Figures {
            physics_faults: 0,
            takt_s: Some(2.0),
            takt_count: 20,
            sustained_takt_s: Some(2.0),
            first20_takt_s: Some(2.0),
            success_rate: Some(success),
            placed: 0,
            attempts: 0,
            collisions,
            protective_stops: 0,
            parts_lost: 0,
            drops: 0,
            runs: 1,
        };
        assert_eq!(c.violation(&f(0.95, 0)), 0.0);
        assert!(c.violations(&f(0.95, 0)).is_empty());
        assert!((c.violation(&f(0.75, 0)) - 0.2).abs() < 1e-12);
        assert!(c.violation(&f(0.5, 0)) > c.violation(&f(0.75, 0)));
        assert_eq!(c.violation(&f(1.0, 2)), 2.0);
        // Negative control: each miss is named.
        assert_eq!(c.violations(&f(0.5, 2)).len(), 2);
        // A run ended by a physics fault is never feasible, whatever the limits.
        let faulted = Figures {
            physics_faults: 1,
            ..f(1.0, 0)
        };
        assert_eq!(c.violation(&faulted), 1.0);
        assert_eq!(
            c.violations(&faulted),
            vec!["1 runs ended by a physics fault (at most 0)".to_string()]
        );
    }

    #[test]
    fn the_budget_cuts_the_last_round_and_the_same_seed_asks_the_same_candidates() {
        let run = |budget| {
            let mut q = Quadratic {
                unsafe_below: f64::NEG_INFINITY,
                rounds: Vec::new(),
            };
            optimize(&dims(), &settings(budget, 0), &mut q).unwrap()
        };
        let (a, b) = (run(25), run(25));
        assert_eq!(a.len(), 25);
        assert_eq!(a, b);
        assert_eq!(a.last().unwrap().round, 2);
        // A larger budget asks the same first candidates (what resuming relies on).
        assert_eq!(run(40)[..25], a[..]);
    }

    #[test]
    fn the_grid_spends_the_budget_on_even_points_with_both_ends_and_finds_the_nearest_point() {
        // Two keys, budget 20: 4 points each (5 x 5 would be 25), both ends included.
        let g = grid(&dims(), 20);
        assert_eq!(g.len(), 16);
        let xs: Vec<f64> = g.iter().step_by(4).map(|p| p[0]).collect();
        assert_eq!(xs, vec![0.004, 0.0093333, 0.0146667, 0.02]);
        let ns: Vec<f64> = g[..4].iter().map(|p| p[1]).collect();
        assert_eq!(ns, vec![1.0, 3.0, 6.0, 8.0]);
        // An integer key with fewer whole values than points takes each once.
        let mut d = dims();
        d[1].lo = 1.0;
        d[1].hi = 2.0;
        assert_eq!(grid(&d, 20).len(), 8);
        // Through the same rounds and best as the swarm: the grid point nearest the optimum.
        let mut q = Quadratic {
            unsafe_below: f64::NEG_INFINITY,
            rounds: Vec::new(),
        };
        let mut s = settings(20, 0);
        s.optimizer = Optimizer::Grid;
        let evals = optimize(&dims(), &s, &mut q).unwrap();
        assert_eq!(evals.len(), 16);
        assert_eq!(q.rounds, vec![0, 1]);
        assert_eq!(best(&evals).unwrap().values, vec![0.0093333, 6.0]);
        // Negative control: the swarm with the same budget is not held to the grid's points.
        let mut q = Quadratic {
            unsafe_below: f64::NEG_INFINITY,
            rounds: Vec::new(),
        };
        let swarm = optimize(&dims(), &settings(20, 0), &mut q).unwrap();
        assert!(swarm.iter().any(|e| !g.contains(&e.values)));
    }

    #[test]
    fn varied_keys_parse_and_bad_ones_are_refused() {
        let d = parse_vary("gripper.cup_diameter_m=0.004:0.02").unwrap();
        assert_eq!((d.lo, d.hi), (0.004, 0.02));
        assert_eq!(d.snap(0.0123456789), 0.0123457);
        assert_eq!(d.snap(1.0), 0.02);
        for (bad, why) in [
            ("k=1:1", "reversed"),
            ("k=2:1", "reversed"),
            ("k=1", "LO:HI"),
            ("k=a:2", "finite"),
            ("k=1:inf", "finite"),
            ("nokey", "KEY=LO:HI"),
            ("a..b=1:2", "key path"),
        ] {
            let e = parse_vary(bad).unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
        let e = parse_varies(&["k=1:2".into(), "k=3:4".into()]).unwrap_err().to_string();
        assert!(e.contains("twice"), "{e}");
    }
}
