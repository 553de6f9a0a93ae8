//! A run's `summary.json`: its summary in the layout run folders have always had (field order
//! and names kept, so files compare across versions).
//!
//! Units: s, mm and deg where a name says so, counts.

use serde::ser::{Serialize, SerializeMap, Serializer};

use super::Summary;
use crate::sensor::RecognitionReport;

/// A run's summary as `summary.json` writes it.
#[derive(Debug, Clone, Copy)]
pub struct RunSummary<'a> {
    /// The run's summary.
    pub summary: &'a Summary,
    /// Whether the run charged fixed compute budgets.
    pub deterministic: bool,
    /// Its recognition results, one report each (empty if the run kept none).
    pub per_capture: &'a [RecognitionReport],
}

impl Serialize for RunSummary<'_> {
    fn serialize<S: Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        let s = self.summary;
        let t = &s.tally;
        let mut m = ser.serialize_map(None)?;
        m.serialize_entry("workpiece", &t.workpiece)?;
        m.serialize_entry("seed", &t.seed)?;
        m.serialize_entry("deterministic", &self.deterministic)?;
        m.serialize_entry("attempts", &t.attempts)?;
        m.serialize_entry("placed", &t.placed)?;
        m.serialize_entry("success_rate", &s.success_rate)?;
        m.serialize_entry("takt", &s.takt)?;
        m.serialize_entry("takt_excl_refills", &s.takt_excl_refills)?;
        m.serialize_entry("reference_takt_s", &s.reference_takt_s)?;
        m.serialize_entry("mean_pick_s", &s.mean_pick_s)?;
        m.serialize_entry("mean_place_s", &s.mean_place_s)?;
        m.serialize_entry("mean_compute_s", &s.mean_compute)?;
        // Count and total (a table row writes count and mean).
        m.serialize_entry("sensor_stalls", &t.sensor_waits)?;
        m.serialize_entry("compute_stalls", &t.compute_waits)?;
        m.serialize_entry("protective_stops", &t.faults.protective_stops)?;
        m.serialize_entry("collisions", &t.faults.collisions)?;
        m.serialize_entry("drops", &t.faults.drops)?;
        m.serialize_entry("parts_lost", &t.faults.parts_lost)?;
        m.serialize_entry("captures", &t.captures)?;
        m.serialize_entry("refills", &t.refills)?;
        m.serialize_entry("agitations", &t.agitations)?;
        m.serialize_entry("place_tray_exchanges", &t.place_tray_exchanges)?;
        m.serialize_entry("peak_demand_ratio", &t.peak_demand_ratio)?;
        m.serialize_entry("saturated_s", &t.saturated_s)?;
        m.serialize_entry("max_tracking_error_deg", &t.max_tracking_error_deg)?;
        m.serialize_entry("grasps", &t.grasps)?;
        m.serialize_entry("blind_picks", &t.blind_picks)?;
        m.serialize_entry("results_used", &t.results_used)?;
        m.serialize_entry("picks_per_capture", &s.picks_per_capture)?;
        m.serialize_entry("misrecognised", &t.misrecognised)?;
        m.serialize_entry("recognition", &s.recognition)?;
        m.serialize_entry("recognition_per_capture", self.per_capture)?;
        m.serialize_entry("ended", &t.ended)?;
        m.serialize_entry("sim_time_s", &t.sim_time_s)?;
        // Every collision, stop, lost or misplaced part, physics fault and large step at a
        // motion's start, as takt.json lists a batch's (added last: the fields before keep their
        // order).
        m.serialize_entry("incidents", &t.incidents)?;
        // How the placed parts lie against their place poses (added last, as incidents).
        m.serialize_entry("placement", &s.placement)?;
        // The takt by what happened in its intervals (added last, as placement).
        m.serialize_entry("takt_by_cause", &super::table::takt_by_cause_json(s))?;
        m.end()
    }
}
