//! Build script: tells the code which parry3d release it is built with (from `Cargo.lock`), so
//! the convex decompositions kept on disk (`src/physics/shapes/decomposition_cache.rs`) are
//! keyed by the exact release that computed them.

fn main() {
    println!("cargo:rerun-if-changed=Cargo.lock");
    let lock = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.lock")).unwrap_or_default();
    // `[[package]]` entries: `name = "parry3d"` followed by its `version = "..."` line.
    let version = lock
        .split("[[package]]")
        .find(|entry| entry.lines().any(|l| l.trim() == "name = \"parry3d\""))
        .and_then(|entry| entry.lines().find_map(|l| l.trim().strip_prefix("version = ")))
        .map(|v| v.trim_matches('"').to_string())
        .unwrap_or_else(|| "unknown".to_string());
    println!("cargo:rustc-env=BINPICK_PARRY3D_VERSION={version}");
}
