//! The per-frame timeline (`vtfarm submit` writes it beside each frame, the
//! dashboard shows it for the frame on view): one row for the master and one
//! per worker, with their phases (base frame, set-up, packages in flight,
//! packages computing) from the frame's statistics, and for a progressive
//! frame (the view) a `view` row of its stages as they went on view; the
//! gaps are idle time.

use vtfarm_imaging::escape_html;
use vtfarm_proto::{FrameStats, PhaseKind};

const ROW: f64 = 28.0;
const LABEL: f64 = 150.0;
const PLOT: f64 = 900.0;

/// The frame's timeline as a self-contained SVG document.
pub fn timeline_svg(stats: &FrameStats) -> String {
    let mut rows: Vec<&str> = vec!["master"];
    for p in &stats.phases {
        if !rows.contains(&p.who.as_str()) {
            rows.push(&p.who);
        }
    }
    let end = (stats.phases.iter())
        .map(|p| p.end_micros)
        .max()
        .unwrap_or(0)
        .max(1) as f64;
    let x = |micros: u64| LABEL + micros as f64 / end * PLOT;
    let height = ROW * (rows.len() as f64 + 2.0);
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{height}\" font-family=\"sans-serif\" font-size=\"12\">\n",
        LABEL + PLOT + 20.0
    );
    for (i, who) in rows.iter().enumerate() {
        let y = ROW * i as f64;
        svg += &format!(
            "<text x=\"4\" y=\"{}\">{}</text>\n<rect x=\"{LABEL}\" y=\"{}\" width=\"{PLOT}\" height=\"{}\" fill=\"#eeeeee\"/>\n",
            y + ROW * 0.65,
            escape_html(who),
            y + 4.0,
            ROW - 8.0
        );
    }
    for p in &stats.phases {
        let row = rows.iter().position(|w| *w == p.who).unwrap_or(0);
        let (x0, x1) = (x(p.start_micros), x(p.end_micros));
        svg += &format!(
            "<rect x=\"{x0:.1}\" y=\"{}\" width=\"{:.1}\" height=\"{}\" fill=\"{}\" stroke=\"white\" stroke-width=\"0.5\"><title>{:?} {:.1}-{:.1} ms</title></rect>\n",
            ROW * row as f64 + 4.0,
            (x1 - x0).max(0.5),
            ROW - 8.0,
            color(p.kind),
            p.kind,
            p.start_micros as f64 / 1e3,
            p.end_micros as f64 / 1e3
        );
    }
    let legend_y = ROW * rows.len() as f64 + ROW * 0.7;
    let kinds = [
        (PhaseKind::Base, "base frame"),
        (PhaseKind::Setup, "set-up"),
        (PhaseKind::Sending, "package/result in flight"),
        (PhaseKind::Package, "package"),
        (PhaseKind::Shown, "view stage"),
    ];
    for (k, (kind, name)) in kinds.iter().enumerate() {
        let lx = LABEL + 180.0 * k as f64;
        svg += &format!(
            "<rect x=\"{lx}\" y=\"{}\" width=\"12\" height=\"12\" fill=\"{}\"/><text x=\"{}\" y=\"{legend_y}\">{name}</text>\n",
            legend_y - 10.0,
            color(*kind),
            lx + 16.0
        );
    }
    svg += &format!(
        "<text x=\"4\" y=\"{legend_y}\">{:.1} ms</text>\n</svg>\n",
        end / 1e3
    );
    svg
}

fn color(kind: PhaseKind) -> &'static str {
    match kind {
        PhaseKind::Base => "#8e6bbf",
        PhaseKind::Setup => "#e8a33d",
        PhaseKind::Sending => "#5b9bd5",
        PhaseKind::Package => "#4caf50",
        PhaseKind::Shown => "#d9534f",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtfarm_proto::FramePhase;

    #[test]
    fn every_phase_is_a_bar_in_its_workers_row() {
        let phase = |who: &str, kind, start_micros, end_micros| FramePhase {
            who: who.into(),
            kind,
            start_micros,
            end_micros,
        };
        let stats = FrameStats {
            phases: vec![
                phase("master", PhaseKind::Base, 0, 400),
                phase("w<1>", PhaseKind::Setup, 0, 100),
                phase("w<1>", PhaseKind::Sending, 100, 110),
                phase("w<1>", PhaseKind::Package, 110, 1000),
            ],
            ..FrameStats::default()
        };
        let svg = timeline_svg(&stats);
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        // Two row backgrounds, four phases, five legend boxes.
        assert_eq!(svg.matches("<rect").count(), 2 + 4 + 5);
        assert!(svg.contains("w&lt;1&gt;"), "names are escaped");
        // The last phase ends at the right edge of the plot.
        assert!(svg.contains("Package 0.1-1.0 ms"), "{svg}");
        assert!(svg.contains(&format!("x=\"{:.1}\"", LABEL + 0.11 * PLOT)));
    }
}
