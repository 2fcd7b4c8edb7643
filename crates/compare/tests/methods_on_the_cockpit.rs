//! Every reflection method on the cockpit against the per-pixel reference:
//! each is closer to it than the plain environment map, by the same figures
//! `vtfarm compare` prints.

use vtfarm_compare::{run_all, sheet, standard_methods};
use vtfarm_method::{OwnedFrame, ReflectionMethod, VertexTracing};
use vtfarm_vertex::VertexSettings;

#[test]
fn every_method_is_closer_to_the_reference_than_the_environment_map() {
    let owned = OwnedFrame::cockpit(0.3, 320, 180);
    let base = owned.base_frame();
    let frame = owned.frame();
    let vertex = VertexSettings::default();
    let methods = standard_methods(vertex);
    let methods: Vec<&dyn ReflectionMethod> = methods.iter().map(|m| m.as_ref()).collect();
    let runs = run_all(
        &frame,
        &base,
        &VertexTracing::reference(),
        &methods,
        &mut |_| {},
    );
    let names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "reference",
            "preview",
            "refine",
            "full",
            "cubemap",
            "cubemap-grid",
            "pvrr",
            "envmap"
        ]
    );
    let envmap = runs.last().unwrap();
    for run in &runs {
        let f = run.figures();
        eprintln!(
            "{:<13} MAE {:.3} off {:.3}% reflected MAE {:.3} rays {} searches {}",
            f.method,
            f.mean_abs,
            f.share_off * 100.0,
            f.reflected_mean_abs,
            f.rays,
            f.searches
        );
        assert_eq!(
            run.image.components().mask,
            runs[0].image.components().mask,
            "{}: the reflector's pixels",
            run.name
        );
    }
    assert_eq!(runs[0].error.mean_abs, 0.0);
    assert!(runs[0].error.pixels > 2000);
    for run in &runs[1..runs.len() - 1] {
        assert!(
            run.error.mean_abs < envmap.error.mean_abs,
            "{}: MAE {} vs envmap {}",
            run.name,
            run.error.mean_abs,
            envmap.error.mean_abs
        );
        assert!(
            run.reflected_mean_abs < envmap.reflected_mean_abs,
            "{}: reflected MAE {} vs envmap {}",
            run.name,
            run.reflected_mean_abs,
            envmap.reflected_mean_abs
        );
    }
    // Full vertex tracing is within 8/255 of the reference almost everywhere.
    assert!(runs[3].error.share_off < 0.01, "{:?}", runs[3].error);
    let sheet = sheet(&runs);
    assert!(sheet.width > runs.len() as u32 * 32);
}
