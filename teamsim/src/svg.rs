//! The picture of a match: the field with robots (the goer ringed), the true ball and its
//! recent track, and below it a timeline of who went when.

use std::fmt::Write;

use super::{Simulation, Snapshot};

const PX_PER_M: f64 = 60.0;

/// Colours of robots 1, 2, …
const COLOURS: [&str; 8] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

fn colour(i: usize) -> &'static str {
    COLOURS[i % COLOURS.len()]
}

/// The SVG document of `sim` as it stands (usually at the end of the run).
pub fn render(sim: &Simulation) -> String {
    let f = sim.config().field;
    let (hx, hy) = (f.length_m / 2.0 + f.border_m, f.width_m / 2.0 + f.border_m);
    let field_w = 2.0 * hx * PX_PER_M;
    let field_h = 2.0 * hy * PX_PER_M;
    let n = sim.robots.len();
    let margin = 20.0;
    let lane = 18.0;
    let tl_top = margin + field_h + 40.0;
    let width = field_w + 2.0 * margin;
    let height = tl_top + lane * (n as f64 + 1.0) + 40.0;
    // Field coordinates → pixels (y up on the field, down in SVG).
    let px = |x: f64| margin + (x + hx) * PX_PER_M;
    let py = |y: f64| margin + (hy - y) * PX_PER_M;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r##"<rect width="100%" height="100%" fill="#ffffff"/>"##);
    let _ = writeln!(
        s,
        r##"<rect x="{:.1}" y="{:.1}" width="{field_w:.1}" height="{field_h:.1}" fill="#3a8f3a"/>"##,
        margin, margin
    );
    // Lines, centre circle, goals.
    let (lx, ly) = (f.length_m / 2.0, f.width_m / 2.0);
    let _ = writeln!(
        s,
        r##"<g stroke="#ffffff" stroke-width="2" fill="none"><rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}"/><line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}"/><circle cx="{:.1}" cy="{:.1}" r="{:.1}"/></g>"##,
        px(-lx),
        py(ly),
        2.0 * lx * PX_PER_M,
        2.0 * ly * PX_PER_M,
        px(0.0),
        py(ly),
        px(0.0),
        py(-ly),
        px(0.0),
        py(0.0),
        0.75 * PX_PER_M
    );
    let g = f.goal_width_m / 2.0;
    for (x, c) in [(-lx, "#f1c40f"), (lx, "#3498db")] {
        let _ = writeln!(
            s,
            r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{c}" stroke-width="6"/>"#,
            px(x),
            py(g),
            px(x),
            py(-g)
        );
    }
    // The ball's track over the last 20 s of snapshots.
    let last_t = sim.snapshots.last().map_or(0.0, |s| s.t_s);
    let recent: Vec<&Snapshot> = sim
        .snapshots
        .iter()
        .filter(|s| s.t_s >= last_t - 20.0)
        .collect();
    if recent.len() > 1 {
        let pts: Vec<String> = recent
            .iter()
            .map(|s| format!("{:.1},{:.1}", px(s.ball.x), py(s.ball.y)))
            .collect();
        let _ = writeln!(
            s,
            r##"<polyline points="{}" fill="none" stroke="#ffffff" stroke-opacity="0.6" stroke-width="1.5" stroke-dasharray="4 3"/>"##,
            pts.join(" ")
        );
    }
    if let Some(snap) = sim.snapshots.last() {
        let kr = f.kinematics.radius_m * PX_PER_M;
        for o in &snap.opponents {
            let _ = writeln!(
                s,
                r##"<circle cx="{:.1}" cy="{:.1}" r="{:.1}" fill="#222222" stroke="#ffffff"/>"##,
                px(o.x),
                py(o.y),
                f.opponent_kinematics.radius_m * PX_PER_M
            );
        }
        for (i, pose) in snap.robots.iter().enumerate() {
            let (cx, cy) = (px(pose.at.x), py(pose.at.y));
            if snap.going.get(i).copied().unwrap_or(false) {
                let _ = writeln!(
                    s,
                    r##"<circle cx="{cx:.1}" cy="{cy:.1}" r="{:.1}" fill="none" stroke="#ffeb3b" stroke-width="4"/>"##,
                    kr + 5.0
                );
            }
            let (hxp, hyp) = (
                cx + kr * 1.4 * pose.theta_rad.cos(),
                cy - kr * 1.4 * pose.theta_rad.sin(),
            );
            let _ = writeln!(
                s,
                r##"<circle cx="{cx:.1}" cy="{cy:.1}" r="{kr:.1}" fill="{}" stroke="#ffffff"/><line x1="{cx:.1}" y1="{cy:.1}" x2="{hxp:.1}" y2="{hyp:.1}" stroke="#ffffff" stroke-width="2"/><text x="{cx:.1}" y="{:.1}" text-anchor="middle" fill="#ffffff" font-weight="bold">{}</text>"##,
                colour(i),
                cy + 4.0,
                i + 1
            );
        }
        let _ = writeln!(
            s,
            r##"<circle cx="{:.1}" cy="{:.1}" r="{:.1}" fill="#ff6600" stroke="#000000"/>"##,
            px(snap.ball.x),
            py(snap.ball.y),
            (f.ball.radius_m * PX_PER_M).max(4.0)
        );
        let _ = writeln!(
            s,
            r##"<text x="{:.1}" y="{:.1}" fill="#000000">t = {:.1} s · ringed: going to the ball · goals {}–{}</text>"##,
            margin,
            margin + field_h + 16.0,
            snap.t_s,
            sim.world.goals_for,
            sim.world.goals_against
        );
    }
    // Timeline: a lane per robot, bars where it went; the top lane shows ball visibility.
    let t_end = sim.time_s().max(1e-9);
    let tx = |t: f64| margin + t / t_end * field_w;
    let _ = writeln!(
        s,
        r##"<text x="{:.1}" y="{:.1}" fill="#000000">timeline 0–{:.0} s: ball visible (grey), going to the ball (per robot)</text>"##,
        margin,
        tl_top - 6.0,
        t_end
    );
    for &(a, b) in &sim.timeline.visible {
        let _ = writeln!(
            s,
            r##"<rect x="{:.2}" y="{tl_top:.1}" width="{:.2}" height="{:.1}" fill="#bbbbbb"/>"##,
            tx(a),
            (tx(b) - tx(a)).max(0.3),
            lane - 4.0
        );
    }
    for (i, spans) in sim.timeline.going.iter().enumerate() {
        let y = tl_top + lane * (i as f64 + 1.0);
        let _ = writeln!(
            s,
            r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#dddddd"/><text x="2" y="{:.1}" fill="#000000">{}</text>"##,
            margin,
            y + (lane - 4.0) / 2.0,
            margin + field_w,
            y + (lane - 4.0) / 2.0,
            y + 11.0,
            i + 1
        );
        for &(a, b) in spans {
            let _ = writeln!(
                s,
                r#"<rect x="{:.2}" y="{y:.1}" width="{:.2}" height="{:.1}" fill="{}"/>"#,
                tx(a),
                (tx(b) - tx(a)).max(0.3),
                lane - 4.0,
                colour(i)
            );
        }
    }
    let _ = writeln!(s, "</svg>");
    s
}
