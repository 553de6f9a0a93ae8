//! Integration tests, one binary: the command line end to end on good and bad input.

mod cad_drops;
mod cad_grasp;
mod cad_parts;
mod cad_run;
mod cli_bad_input;
mod cli_pile;
mod cli_robot;
mod cli_sense;
mod expect;
mod faults;
mod fuzz;
mod golden;
mod mesh_export;
mod physics;
mod planning;
mod recording;
mod scenario;
mod sensing;
mod servo;
mod support;
mod sweep;
mod trajectory;
mod tune;
