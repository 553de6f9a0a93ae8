//! A picture of a part model as SVG: six orthographic views of its mesh (top, front, side over
//! bottom, back, other side, so that every face is seen square on), shaded, with the faces the
//! cell's cup seals on in green, their cup-fit regions dotted and the cup drawn at each face's
//! site ([`PartModel::cup_sites`]: the grasp selector's).
//!
//! Units: m in, pixels out (one scale for the six views). Frames: top looks down the part's -z
//! (x right, y up), front looks along +y (x right, z up), side looks along -x (y right, z up);
//! bottom looks along +z (x right, y down), back along -y (x left, z up), other side along +x
//! (y left, z up). No view is mirrored.

use std::fmt::Write;

use nalgebra::{Point3, Vector3};

use super::model::PartModel;

/// Pixels per view (square).
const VIEW_PX: f64 = 300.0;
/// Margin around the views (px).
const PAD_PX: f64 = 20.0;
/// Where the first row of views starts (px from the top), and the height of a row's caption.
const TOP_PX: f64 = 40.0;
const CAPTION_PX: f64 = 24.0;
/// Views per row.
const PER_ROW: usize = 3;
/// The most cup-fit centres drawn per face.
const MAX_DOTS: usize = 600;

struct View {
    name: &'static str,
    /// Direction toward the viewer.
    toward: Vector3<f64>,
    h: Vector3<f64>,
    v: Vector3<f64>,
}

/// The six views: top, front, side; bottom, back, other side (each `h` × `v` = `toward`).
fn views() -> [View; 6] {
    [
        View {
            name: "top (looking down z)",
            toward: Vector3::z(),
            h: Vector3::x(),
            v: Vector3::y(),
        },
        View {
            name: "front (looking along +y)",
            toward: -Vector3::y(),
            h: Vector3::x(),
            v: Vector3::z(),
        },
        View {
            name: "side (looking along -x)",
            toward: Vector3::x(),
            h: Vector3::y(),
            v: Vector3::z(),
        },
        View {
            name: "bottom (looking up along +z)",
            toward: -Vector3::z(),
            h: Vector3::x(),
            v: -Vector3::y(),
        },
        View {
            name: "back (looking along -y)",
            toward: Vector3::y(),
            h: -Vector3::x(),
            v: Vector3::z(),
        },
        View {
            name: "other side (looking along +x)",
            toward: -Vector3::x(),
            h: -Vector3::y(),
            v: Vector3::z(),
        },
    ]
}

/// The cup's site on each face of a part model, in [`PartModel::faces`] order, as
/// [`PartModel::cup_sites`] gives them (part frame, with the distance to the nearest edge).
pub type CupSites = [Option<(Point3<f64>, f64)>];

/// The SVG text of the picture, titled `title`, with the cup drawn at each face's `sites` entry.
pub fn picture(model: &PartModel, title: &str, sites: &CupSites) -> String {
    let largest = model.size_m.iter().cloned().fold(1e-9, f64::max);
    let scale = (VIEW_PX - 2.0 * PAD_PX) / largest;
    let rows = views().len().div_ceil(PER_ROW) as f64;
    let width = PER_ROW as f64 * VIEW_PX + 2.0 * PAD_PX;
    let height = TOP_PX + rows * (VIEW_PX + CAPTION_PX) + 86.0;
    let grasp_of = grasp_face_of_triangles(model);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width:.0}\" height=\"{height:.0}\" viewBox=\"0 0 {width:.0} {height:.0}\" font-family=\"sans-serif\" font-size=\"12\">"
    );
    let _ = writeln!(s, "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>");
    let _ = writeln!(
        s,
        "<text x=\"{PAD_PX}\" y=\"22\" font-size=\"15\">{}</text>",
        escape(title)
    );
    for (vi, view) in views().iter().enumerate() {
        draw_view(&mut s, model, view, vi, scale, &grasp_of, sites);
    }
    draw_legend(&mut s, model, scale, TOP_PX + rows * (VIEW_PX + CAPTION_PX) + 16.0);
    s.push_str("</svg>\n");
    s
}

/// For each mesh triangle, the index of the cup-taking face it belongs to, if any.
fn grasp_face_of_triangles(model: &PartModel) -> Vec<Option<usize>> {
    let mut grasp_of = vec![None; model.mesh.triangles.len()];
    for (i, f) in model.faces.iter().enumerate() {
        if f.fit.takes_cup() {
            for &k in &f.face.triangles {
                grasp_of[k] = Some(i);
            }
        }
    }
    grasp_of
}

/// View number `vi` (rows of [`PER_ROW`]): its frame and caption, the shaded mesh, the cup fits
/// facing the viewer and the centre of mass.
fn draw_view(
    s: &mut String,
    model: &PartModel,
    view: &View,
    vi: usize,
    scale: f64,
    grasp_of: &[Option<usize>],
    sites: &CupSites,
) {
    let ox = PAD_PX + (vi % PER_ROW) as f64 * VIEW_PX + VIEW_PX / 2.0;
    let top = TOP_PX + (vi / PER_ROW) as f64 * (VIEW_PX + CAPTION_PX);
    let oy = top + VIEW_PX / 2.0;
    let px = |p: &Point3<f64>| (ox + scale * p.coords.dot(&view.h), oy - scale * p.coords.dot(&view.v));
    let _ = writeln!(
        s,
        "<rect x=\"{:.1}\" y=\"{top:.1}\" width=\"{:.1}\" height=\"{VIEW_PX:.1}\" fill=\"none\" stroke=\"#ccc\"/>",
        ox - VIEW_PX / 2.0 + 4.0,
        VIEW_PX - 8.0
    );
    let _ = writeln!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
        ox,
        top + VIEW_PX + 16.0,
        view.name
    );
    draw_triangles(s, &model.mesh, view, &px, grasp_of);
    draw_cup_fits(s, model, view, &px, scale, sites);
    // The centre of mass.
    let (x, y) = px(&model.mass.com_m);
    let _ = writeln!(
        s,
        "<g stroke=\"#c00\" stroke-width=\"1.2\"><line x1=\"{:.2}\" y1=\"{y:.2}\" x2=\"{:.2}\" y2=\"{y:.2}\"/><line x1=\"{x:.2}\" y1=\"{:.2}\" x2=\"{x:.2}\" y2=\"{:.2}\"/></g>",
        x - 5.0,
        x + 5.0,
        y - 5.0,
        y + 5.0
    );
}

/// The triangles facing the viewer, far ones first, shaded by their slant and their depth (the
/// nearest full, the farthest at [`FAR_SHADE`]: a well's floor shows darker than the face it is
/// sunk in); those of cup faces green.
fn draw_triangles(
    s: &mut String,
    mesh: &super::mesh::Mesh,
    view: &View,
    px: &impl Fn(&Point3<f64>) -> (f64, f64),
    grasp_of: &[Option<usize>],
) {
    let mut order: Vec<(f64, usize)> = (0..mesh.triangles.len())
        .filter_map(|k| {
            let n = mesh.area_normal(k);
            if n.dot(&view.toward) <= 0.0 {
                return None;
            }
            let [a, b, c] = mesh.corners(k);
            Some(((a.coords + b.coords + c.coords).dot(&view.toward), k))
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    // The mesh's depth range along the view (three times a centroid's, as `order` holds them).
    let (near, far) = mesh.vertices_m.iter().fold((f64::MIN, f64::MAX), |(hi, lo), p| {
        let d = 3.0 * p.coords.dot(&view.toward);
        (hi.max(d), lo.min(d))
    });
    for (depth, k) in order {
        let n = mesh.area_normal(k).normalize();
        let nearness = if near > far { (depth - far) / (near - far) } else { 1.0 };
        let light = (0.35 + 0.65 * n.dot(&view.toward).abs()) * (FAR_SHADE + (1.0 - FAR_SHADE) * nearness);
        let (r, g, b) = if grasp_of[k].is_some() {
            (60.0, 170.0, 80.0)
        } else {
            (170.0, 170.0, 180.0)
        };
        let [a, bb, c] = mesh.corners(k).map(|p| px(&p));
        let col = format!("rgb({:.0},{:.0},{:.0})", r * light, g * light, b * light);
        let _ = writeln!(
            s,
            "<polygon points=\"{:.2},{:.2} {:.2},{:.2} {:.2},{:.2}\" fill=\"{col}\" stroke=\"{col}\" stroke-width=\"0.4\"/>",
            a.0, a.1, bb.0, bb.1, c.0, c.1
        );
    }
}

/// The shade of the triangles farthest from the viewer, against the nearest's (1).
const FAR_SHADE: f64 = 0.6;

/// Cup-fit regions (dotted) and the cup at its site, on the cup faces looking at the viewer.
fn draw_cup_fits(
    s: &mut String,
    model: &PartModel,
    view: &View,
    px: &impl Fn(&Point3<f64>) -> (f64, f64),
    scale: f64,
    sites: &CupSites,
) {
    for (f, site) in model.faces.iter().zip(sites).filter(|(f, _)| f.fit.takes_cup()) {
        if f.face.normal.dot(&view.toward) < 0.99 {
            continue;
        }
        let step = f.fit.centres.len().div_ceil(MAX_DOTS).max(1);
        for c in f.fit.centres.iter().step_by(step) {
            let (x, y) = px(&f.face.to_part(c));
            let _ = writeln!(s, "<circle cx=\"{x:.2}\" cy=\"{y:.2}\" r=\"0.9\" fill=\"#0a5\"/>");
        }
        if let Some((site, _)) = site {
            let (x, y) = px(site);
            let _ = writeln!(
                s,
                "<circle cx=\"{x:.2}\" cy=\"{y:.2}\" r=\"{:.2}\" fill=\"none\" stroke=\"#c30\" stroke-width=\"1.5\" stroke-dasharray=\"4 2\"/>",
                scale * model.cup.diameter_m / 2.0
            );
        }
    }
}

/// The legend under the views (its first line at `legend_y`, px) and the most likely resting
/// poses (poses alike as one), four to a line.
fn draw_legend(s: &mut String, model: &PartModel, scale: f64, legend_y: f64) {
    let _ = writeln!(
        s,
        "<text x=\"{PAD_PX}\" y=\"{legend_y:.0}\">green: faces the {:.1} mm cup seals on (margin {:.1} mm); dots: admissible cup centres; dashed: the cup at its site; red cross: centre of mass. Scale: {:.0} px per mm.</text>",
        model.cup.diameter_m * 1e3,
        model.cup.face_margin_m * 1e3,
        scale / 1e3
    );
    // Poses alike (a hex prism's six flats) as one: the first one's normal, how many, their
    // likelihood summed.
    let poses: Vec<String> = super::poses::alike_groups(&model.poses, &[])
        .iter()
        .take(6)
        .map(|g| {
            let p = &model.poses[g[0]];
            let count = if g.len() > 1 {
                format!(" x{}", g.len())
            } else {
                String::new()
            };
            format!(
                "[{:.2} {:.2} {:.2}]{count} {:.0} %",
                p.normal.x,
                p.normal.y,
                p.normal.z,
                100.0 * g.iter().map(|&i| model.poses[i].likelihood).sum::<f64>()
            )
        })
        .collect();
    for (i, line) in poses.chunks(4).enumerate() {
        let head = if i == 0 {
            "resting on (down normal, likelihood): "
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "<text x=\"{PAD_PX}\" y=\"{:.0}\">{head}{}</text>",
            legend_y + 20.0 * (i + 1) as f64,
            escape(&line.join(", "))
        );
    }
}

fn escape(t: &str) -> String {
    t.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step seen from above: a 10 mm slab with a 4 mm block on it. Both tops face the viewer
    /// square on, so only their depth tells them apart: the slab's top (4 mm farther) is drawn
    /// darker than the block's. Control: their sides, seen edge on, are not drawn.
    /// Every side of a part is seen square on in exactly one view, and no view is mirrored (a
    /// view's right and up make a right-handed frame with the direction toward the viewer).
    /// Control: the three views the picture had before leave three sides unseen.
    #[test]
    fn every_side_is_seen_in_one_unmirrored_view() {
        let seen_by = |views: &[View], side: Vector3<f64>| views.iter().filter(|v| v.toward == side).count();
        let sides = [Vector3::x(), Vector3::y(), Vector3::z()]
            .into_iter()
            .flat_map(|a| [a, -a]);
        let all = views();
        for side in sides.clone() {
            assert_eq!(seen_by(&all, side), 1, "{side:?}");
        }
        for v in &all {
            assert_eq!(v.h.cross(&v.v), v.toward, "{}", v.name);
        }
        let unseen = sides.filter(|&side| seen_by(&all[..3], side) == 0).count();
        assert_eq!(unseen, 3);
    }

    #[test]
    fn a_face_farther_from_the_viewer_is_drawn_darker() {
        use super::super::tessellate::box_mesh;
        let slab = box_mesh(Vector3::new(0.0, 0.0, 0.001), Vector3::new(0.005, 0.005, 0.001));
        let block = box_mesh(Vector3::new(0.0, 0.0, 0.004), Vector3::new(0.002, 0.002, 0.002));
        let n = slab.vertices_m.len() as u32;
        let mesh = super::super::mesh::Mesh {
            vertices_m: slab.vertices_m.iter().chain(&block.vertices_m).copied().collect(),
            triangles: slab
                .triangles
                .iter()
                .copied()
                .chain(block.triangles.iter().map(|t| t.map(|i| i + n)))
                .collect(),
        };
        let view = View {
            name: "top",
            toward: Vector3::z(),
            h: Vector3::x(),
            v: Vector3::y(),
        };
        let mut s = String::new();
        draw_triangles(
            &mut s,
            &mesh,
            &view,
            &|p: &Point3<f64>| (p.x * 1e3, p.y * 1e3),
            &vec![None; mesh.triangles.len()],
        );
        // Each drawn triangle's red channel, far first: the slab's top at z = 2 mm (two
        // triangles), the block's at 6 mm (two); the mesh spans z = 0 to 6 mm, so the slab's top
        // is a third of the way from the farthest to the nearest.
        let reds: Vec<f64> = s
            .lines()
            .map(|l| {
                l.split("fill=\"rgb(")
                    .nth(1)
                    .unwrap()
                    .split(',')
                    .next()
                    .unwrap()
                    .parse()
                    .unwrap()
            })
            .collect();
        assert_eq!(reds.len(), 4, "{s}");
        let (slab_top, block_top) = (reds[0], reds[3]);
        assert!(slab_top < block_top, "{s}");
        let expected = FAR_SHADE + (1.0 - FAR_SHADE) / 3.0;
        assert!(
            (slab_top / block_top - expected).abs() < 0.02,
            "{slab_top} / {block_top}"
        );
    }
}
