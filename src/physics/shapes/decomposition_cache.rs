//! A disk cache of convex decompositions: parry's VHACD of a CAD shell takes about a second
//! (a bored standoff, a tab with a hole), and every command on the part (`part`, `check`, each
//! `batch` or `run` process) would pay it again.
//!
//! Job: key a shell's decomposition by everything it is computed from (the shell's vertices and
//! triangles bit for bit, the VHACD parameters, this cache's format and the exact parry3d
//! release), keep each piece's vertices (f32 bit patterns, so a cached decomposition is the
//! computed one, bit for bit: no result changes) in one small file per shell, and read it back
//! only when it is whole.
//! A missing, short or malformed file is recomputed; a write goes to a temporary file renamed into
//! place, so a reader never sees half a file. Where no folder is known, nothing is cached.
//!
//! The folder: `$BINPICK_CACHE_DIR`, else `$XDG_CACHE_HOME/binpick`, else `$HOME/.cache/binpick`.
//! Setting `BINPICK_CACHE_DIR` to an empty value turns the cache off.
//!
//! Units: the physics world's (rapier units, the part frame).

use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

use rapier3d::math::Vector;

/// What a cached decomposition also depends on besides its inputs: this file's layout (bump the
/// number with it) and the parry3d release that decomposed it (from `Cargo.lock`, by the build
/// script: another release's VHACD may decompose differently).
const FORMAT: &str = concat!("binpick-vhacd-1 parry3d-", env!("BINPICK_PARRY3D_VERSION"));

/// The cache folder from the environment, if any (see the module header).
pub fn folder() -> Option<PathBuf> {
    match std::env::var_os("BINPICK_CACHE_DIR") {
        Some(d) if d.is_empty() => None,
        Some(d) => Some(PathBuf::from(d)),
        None => std::env::var_os("XDG_CACHE_HOME")
            .filter(|d| !d.is_empty())
            .map(|d| PathBuf::from(d).join("binpick"))
            .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("binpick"))),
    }
}

/// The pieces' vertices of the decomposition of the shell (`verts`, `tris`) with `params` (their
/// text: every field), from `dir` when a whole file is there, else from `compute`, then stored.
pub fn decomposition(
    dir: Option<&Path>,
    verts: &[Vector],
    tris: &[[u32; 3]],
    params: &str,
    compute: impl FnOnce() -> Vec<Vec<Vector>>,
) -> Vec<Vec<Vector>> {
    let Some(dir) = dir else {
        return compute();
    };
    let path = dir.join(format!("vhacd-{:016x}.bin", key(verts, tris, params)));
    if let Some(pieces) = std::fs::read(&path).ok().and_then(|b| decode(&b)) {
        return pieces;
    }
    let pieces = compute();
    // A cache that cannot be written (a read-only home) costs the next process the same second,
    // nothing else.
    let _ = store(dir, &path, &encode(&pieces));
    pieces
}

/// The key of a shell and its parameters.
fn key(verts: &[Vector], tris: &[[u32; 3]], params: &str) -> u64 {
    // SipHash with fixed keys: the same bits give the same key in every process of this build.
    let mut h = std::hash::DefaultHasher::new();
    FORMAT.hash(&mut h);
    params.hash(&mut h);
    verts.len().hash(&mut h);
    for v in verts {
        [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()].hash(&mut h);
    }
    tris.hash(&mut h);
    h.finish()
}

/// Magic bytes at the start of a cache file.
const MAGIC: &[u8; 8] = b"bpvhacd1";

/// The file's bytes: the magic, the piece count (u32), then per piece its vertex count (u32) and
/// its vertices (x, y, z as f32 bit patterns), all little-endian.
fn encode(pieces: &[Vec<Vector>]) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    out.extend((pieces.len() as u32).to_le_bytes());
    for p in pieces {
        out.extend((p.len() as u32).to_le_bytes());
        for v in p {
            for c in [v.x, v.y, v.z] {
                out.extend(c.to_bits().to_le_bytes());
            }
        }
    }
    out
}

/// The pieces of a whole file; `None` for anything else (short, long, another format, a
/// non-finite coordinate, an empty piece).
fn decode(bytes: &[u8]) -> Option<Vec<Vec<Vector>>> {
    let body = bytes.strip_prefix(MAGIC)?;
    let mut words = body.chunks(4).map(|w| Some(u32::from_le_bytes(w.try_into().ok()?)));
    let mut word = || words.next().flatten();
    let count = word()?;
    let mut pieces = Vec::new();
    for _ in 0..count {
        let n = word()?;
        if n == 0 {
            return None;
        }
        let mut piece = Vec::new();
        for _ in 0..n {
            let [x, y, z] = [word()?, word()?, word()?].map(f32::from_bits);
            if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                return None;
            }
            piece.push(Vector::new(x, y, z));
        }
        pieces.push(piece);
    }
    // Whole: nothing after the last piece, not even a byte.
    let read = 4 * (1 + pieces.iter().map(|p| 1 + 3 * p.len()).sum::<usize>());
    (body.len() == read).then_some(pieces)
}

/// Writes `bytes` to `path` through a temporary file in `dir`, renamed into place.
fn store(dir: &Path, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    // Unique per process and per write: shells are decomposed on several threads at once.
    static WRITES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let tmp = dir.join(format!(
        ".{}.{}.{}.tmp",
        path.file_name().and_then(|n| n.to_str()).unwrap_or("vhacd"),
        std::process::id(),
        WRITES.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    ));
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shell() -> (Vec<Vector>, Vec<[u32; 3]>) {
        let verts = vec![
            Vector::new(0.0, 0.0, 0.0),
            Vector::new(1.0, 0.0, 0.0),
            Vector::new(0.0, 1.0, 0.0),
            Vector::new(0.0, 0.0, 1.0),
        ];
        (verts, vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    }

    /// The second process reads what the first computed, bit for bit, without computing; a
    /// changed input or parameter is another entry. Negative controls: a truncated file and a
    /// file with a byte too many are recomputed (and replaced), not read.
    #[test]
    fn a_decomposition_is_computed_once_and_read_back_whole() {
        let dir = std::env::temp_dir().join(format!("binpick-vhacd-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let (verts, tris) = shell();
        let pieces = vec![verts.clone(), vec![Vector::new(0.1, 0.2, f32::MIN_POSITIVE)]];
        let computed = std::cell::Cell::new(0);
        let run = |verts: &[Vector], params: &str| {
            decomposition(Some(&dir), verts, &tris, params, || {
                computed.set(computed.get() + 1);
                pieces.clone()
            })
        };
        assert_eq!(run(&verts, "p"), pieces);
        assert_eq!(run(&verts, "p"), pieces);
        assert_eq!(computed.get(), 1, "the second call computed again");
        let mut moved = verts.clone();
        moved[1].x = f32::from_bits(moved[1].x.to_bits() + 1);
        run(&moved, "p");
        run(&verts, "q");
        assert_eq!(computed.get(), 3, "another shell or parameter read a stale entry");
        let path = dir.join(format!("vhacd-{:016x}.bin", key(&verts, &tris, "p")));
        let whole = std::fs::read(&path).unwrap();
        for broken in [whole[..whole.len() - 1].to_vec(), [whole.clone(), vec![0]].concat()] {
            std::fs::write(&path, &broken).unwrap();
            assert_eq!(run(&verts, "p"), pieces);
        }
        assert_eq!(computed.get(), 5, "a broken file was read");
        assert_eq!(std::fs::read(&path).unwrap(), whole, "the broken file was not replaced");
        // Without a folder nothing is kept.
        decomposition(None, &verts, &tris, "p", || {
            computed.set(computed.get() + 1);
            pieces.clone()
        });
        assert_eq!(computed.get(), 6);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
