//! `vtfarm bench view --browser`: the dashboard in headless Chromium
//! (WebGL2 on SwiftShader, a 1400×1000 window) draws the view itself, and
//! the figures are the page's own timings (`window.vtfarm.viewTimings`:
//! per move `sent`, the time each stage was first drawn and `draw`, how
//! long the draw that first showed its preview took, all `performance.now()`
//! milliseconds). Arrow-key moves, each waited for until its `full` stage
//! is drawn, give each stage's latency; a drag of mouse moves at 30 a
//! second gives how often the preview is on screen while the eye moves.

use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use vtfarm_browser::{Browser, Graphics, Options, left_button};
use vtfarm_master::view::STAGES;

use super::{MOVE_PAUSE, Spread};

/// The window the page is measured in (CSS pixels).
pub(super) const WINDOW: [u32; 2] = [1400, 1000];

/// The drag: mouse moves a second, for how long, and the pixels each goes
/// (a millimetre of eye each); right for the first half, back for the second.
const DRAG_MOVES_PER_SECOND: u32 = 30;
const DRAG_DURATION: Duration = Duration::from_secs(2);
const DRAG_PIXELS: f64 = 1.0;

/// DevTools replies may take this much longer than the page's own waits
/// (which are bounded by `--timeout`), so a page that gives up says why.
const DEVTOOLS_MARGIN: Duration = Duration::from_secs(10);

/// One move's entry in `window.vtfarm.viewTimings` (milliseconds; a stage
/// never drawn is null).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
pub(super) struct ViewTiming {
    sent: f64,
    preview: Option<f64>,
    refine: Option<f64>,
    full: Option<f64>,
    draw: Option<f64>,
}

impl ViewTiming {
    /// When stage `k` (index in [`STAGES`]) was first drawn.
    fn stage(&self, k: usize) -> Option<f64> {
        [self.preview, self.refine, self.full][k]
    }
}

/// One stage over the timed moves (milliseconds).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(super) struct StageFigures {
    quality: &'static str,
    /// The moves that drew the stage.
    drawn: usize,
    /// The stage drawn, less the move's sending.
    since_sent_ms: Option<Spread>,
    /// The same less the move's `draw` (the page's own draw of its preview):
    /// the farm's and the stream's part as the page sees it.
    less_draw_ms: Option<Spread>,
}

/// The drag: moves the page sent and previews it drew within it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(super) struct DragFigures {
    /// From the button's press to its release (the page's clock).
    seconds: f64,
    mouse_moves: usize,
    /// The moves the page sent within the drag (one at a time: a move made
    /// while one is on its way goes when it returns, the newest only).
    moves_sent: usize,
    previews_drawn: usize,
    previews_per_second: f64,
}

/// What the page measured.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(super) struct PageFigures {
    window: [u32; 2],
    /// The arrow-key moves timed (the move loading the scene sends is not).
    key_moves: usize,
    stages: Vec<StageFigures>,
    /// The page's draw of each move's preview.
    draw_ms: Option<Spread>,
    drag: DragFigures,
    /// Every move's timings, as the page recorded them.
    timings: Vec<ViewTiming>,
}

/// Each stage's figures over `moves`: per move, the stage's time less its
/// sending (and less its `draw`), moves without the stage (or without
/// `draw`) left out of that figure.
pub(super) fn stage_figures(moves: &[ViewTiming]) -> Vec<StageFigures> {
    (STAGES.iter().enumerate())
        .map(|(k, quality)| {
            let since_sent: Vec<(f64, Option<f64>)> = (moves.iter())
                .filter_map(|m| Some((m.stage(k)? - m.sent, m.draw)))
                .collect();
            StageFigures {
                quality: quality.name(),
                drawn: since_sent.len(),
                since_sent_ms: Spread::of(since_sent.iter().map(|&(t, _)| t)),
                less_draw_ms: Spread::of(
                    (since_sent.iter()).filter_map(|&(t, draw)| Some(t - draw?)),
                ),
            }
        })
        .collect()
}

/// The drag from `start` to `end` (the page's milliseconds): the moves
/// sent and the previews drawn (of any move) within it.
pub(super) fn drag_figures(
    timings: &[ViewTiming],
    start: f64,
    end: f64,
    mouse_moves: usize,
) -> DragFigures {
    let within = |t: f64| start <= t && t <= end;
    let seconds = (end - start) / 1e3;
    let previews_drawn = (timings.iter())
        .filter(|m| m.preview.is_some_and(within))
        .count();
    DragFigures {
        seconds,
        mouse_moves,
        moves_sent: timings.iter().filter(|m| within(m.sent)).count(),
        previews_drawn,
        previews_per_second: if seconds > 0.0 {
            previews_drawn as f64 / seconds
        } else {
            0.0
        },
    }
}

/// Drives the dashboard at `http` in Chromium on the view of job
/// `source`: `key_moves` arrow-key moves, then the drag. Every wait is
/// bounded by `timeout`; Chromium ends with this function, whichever way.
pub(super) async fn measure(
    chromium: &Path,
    http: SocketAddr,
    source: u64,
    key_moves: usize,
    timeout: Duration,
) -> Result<PageFigures> {
    let options = Options {
        graphics: Graphics::SwiftShader,
        window: WINDOW,
        timeout: timeout + DEVTOOLS_MARGIN,
        // The bench runs the browser from its main thread.
        end_with_this_thread: true,
    };
    let mut page = Page {
        browser: Browser::start(chromium, &options)
            .await
            .context("starting Chromium")?,
        wait_ms: timeout.as_millis(),
    };
    page.call("Page.enable", json!({})).await?;
    page.call("Runtime.enable", json!({})).await?;
    let url = format!("http://{http}/");
    page.call("Page.navigate", json!({ "url": url })).await?;
    (page.browser.event("Page.loadEventFired").await).context("loading the dashboard")?;
    page.choose_source(source).await?;
    // The move to the job's eye that loading the scene sends, untimed.
    page.full_drawn(0).await?;
    for k in 1..=key_moves {
        // Right and back, so the eye stays near the job's.
        let (key, code) = if k % 2 == 1 {
            ("ArrowRight", 39)
        } else {
            ("ArrowLeft", 37)
        };
        page.press(key, code).await?;
        page.full_drawn(k).await?;
        tokio::time::sleep(MOVE_PAUSE).await;
    }
    let (start, end, mouse_moves) = page.drag().await?;
    page.settled().await?;
    let timings = page.eval("window.vtfarm.viewTimings").await?;
    let timings: Vec<ViewTiming> =
        serde_json::from_value(timings).context("the page's viewTimings")?;
    let timed = timings.get(1..=key_moves).unwrap_or_default();
    Ok(PageFigures {
        window: WINDOW,
        key_moves,
        stages: stage_figures(timed),
        draw_ms: Spread::of(timed.iter().filter_map(|m| m.draw)),
        drag: drag_figures(&timings, start, end, mouse_moves),
        timings,
    })
}

/// The dashboard in Chromium, and how long the page may wait for anything.
struct Page {
    browser: Browser,
    wait_ms: u128,
}

impl Page {
    async fn call(&mut self, method: &str, params: Value) -> Result<Value> {
        (self.browser.call(method, params).await).with_context(|| format!("DevTools {method}"))
    }

    async fn eval(&mut self, expression: &str) -> Result<Value> {
        (self.browser.eval(expression).await).context("evaluating on the dashboard")
    }

    /// Resolves when `condition` (JavaScript) holds on the page
    /// ([`vtfarm_master::view_reaches`]); an error naming `what` with
    /// `state` (JavaScript) after the wait.
    async fn until(&mut self, condition: &str, state: &str, what: &str) -> Result<()> {
        let wait = vtfarm_master::view_reaches(condition, "true", state, self.wait_ms as u64);
        let result = self.eval(&wait).await?;
        if result == true {
            return Ok(());
        }
        bail!(
            "{what}: not within {} s; the page has {result}; it logged {:#?}",
            self.wait_ms as f64 / 1e3,
            self.browser.page_log()
        )
    }

    /// Chooses job `source` in the view's selector (once the page lists it)
    /// and waits until the page draws its scene with WebGL2; an error if it
    /// fell back to the master's images.
    async fn choose_source(&mut self, source: u64) -> Result<()> {
        let pick = format!(
            r#"(() => {{
                const select = document.getElementById("view-source");
                const pick = () => {{
                    if (![...select.options].some((o) => o.value === "{source}")) return false;
                    select.value = "{source}";
                    select.dispatchEvent(new Event("change"));
                    return true;
                }};
                if (pick()) return true;
                const retry = () => {{ if (pick()) document.removeEventListener("vtfarm-update", retry); }};
                document.addEventListener("vtfarm-update", retry);
                return true;
            }})()"#
        );
        self.eval(&pick).await?;
        let mode = r#"document.getElementById("view-mode").textContent"#;
        // The page says in its mode line when it cannot draw the scene.
        let drawn_or_not = format!(
            r#"window.vtfarm.glReady === true || !window.vtfarm.gl || {mode}.includes("cannot draw")"#
        );
        let state = format!(r#"{{ mode: {mode} }}"#);
        (self.until(&drawn_or_not, &state, "the scene drawn with WebGL2")).await?;
        if self.eval("window.vtfarm.glReady === true").await? != true {
            let mode = self.eval(mode).await?;
            bail!("the page did not draw the view with WebGL2 (SwiftShader): {mode}");
        }
        Ok(())
    }

    /// Waits until move `index` (the page's order) has drawn its `full` stage.
    async fn full_drawn(&mut self, index: usize) -> Result<()> {
        let done =
            format!("(window.vtfarm.viewTimings[{index}] || {{ full: null }}).full !== null");
        let what = format!("move {index}'s full stage drawn");
        self.until(&done, "{ timings: window.vtfarm.viewTimings }", &what)
            .await
    }

    async fn press(&mut self, key: &str, code: u32) -> Result<()> {
        (self.browser.press(key, code).await).context("DevTools Input.dispatchKeyEvent")
    }

    /// Drags over the view's canvas at [`DRAG_MOVES_PER_SECOND`] for
    /// [`DRAG_DURATION`], each mouse event sent at its time on the clock
    /// whether or not the page has handled the last (as a mouse gives
    /// them; a busy page's input queue coalesces them); answers the drag's
    /// press and release on the page's clock, and the mouse moves made.
    async fn drag(&mut self) -> Result<(f64, f64, usize)> {
        let centre = self
            .eval(
                r#"(() => {
                const canvas = document.getElementById("view-gl");
                canvas.scrollIntoView();
                const r = canvas.getBoundingClientRect();
                return [r.x + r.width / 2, r.y + r.height / 2];
            })()"#,
            )
            .await?;
        let at = |k: usize| centre[k].as_f64().context("the canvas's position");
        let (x, y) = (at(0)?, at(1)?);
        let mouse = |kind: &str, x: f64| left_button(kind, x, y);
        let moves = (DRAG_DURATION.as_secs_f64() * f64::from(DRAG_MOVES_PER_SECOND)) as usize;
        let period = Duration::from_secs(1) / DRAG_MOVES_PER_SECOND;
        // The page's clock at a moment of this one's: the drag's bounds on
        // the page's clock follow from this one's, whenever the page gets
        // to the events.
        let page_clock = self.eval("performance.now()").await?;
        let page_clock = page_clock.as_f64().context("performance.now()")?;
        let clock = tokio::time::Instant::now();
        let on_page = |at: tokio::time::Instant| page_clock + (at - clock).as_secs_f64() * 1e3;
        let mut sent = Vec::with_capacity(moves + 2);
        let press = tokio::time::Instant::now();
        let event = mouse("mousePressed", x);
        sent.push(self.browser.send("Input.dispatchMouseEvent", event).await?);
        let mut to = x;
        for k in 1..=moves {
            tokio::time::sleep_until(press + period * k as u32).await;
            to += if k <= moves / 2 {
                DRAG_PIXELS
            } else {
                -DRAG_PIXELS
            };
            let event = mouse("mouseMoved", to);
            sent.push(self.browser.send("Input.dispatchMouseEvent", event).await?);
        }
        let release = tokio::time::Instant::now();
        let event = mouse("mouseReleased", to);
        sent.push(self.browser.send("Input.dispatchMouseEvent", event).await?);
        for sent in sent {
            (self.browser.reply(sent).await).context("DevTools Input.dispatchMouseEvent")?;
        }
        Ok((on_page(press), on_page(release), moves))
    }

    /// Waits until the page's newest move has drawn its `full` stage and
    /// sent nothing newer for [`MOVE_PAUSE`]: every move of the drag has
    /// its reply, so its timing is listed. (A move made newer on its way
    /// never draws its `full`: the newest is waited for, whichever it is.)
    async fn settled(&mut self) -> Result<()> {
        let deadline = tokio::time::Instant::now() + Duration::from_millis(self.wait_ms as u64);
        let count = "window.vtfarm.viewTimings.length";
        let newest_full =
            "((t) => t.length > 0 && t[t.length - 1].full !== null)(window.vtfarm.viewTimings)";
        loop {
            let what = "the newest move's full stage drawn after the drag";
            (self.until(newest_full, "{ timings: window.vtfarm.viewTimings }", what)).await?;
            let before = self.eval(count).await?;
            tokio::time::sleep(MOVE_PAUSE).await;
            if self.eval(count).await? == before && self.eval(newest_full).await? == true {
                return Ok(());
            }
            if tokio::time::Instant::now() > deadline {
                bail!(
                    "the page kept sending moves for {} s after the drag",
                    self.wait_ms as f64 / 1e3
                );
            }
        }
    }
}

/// The page's figures as text.
pub(super) fn print(figures: &PageFigures) {
    let [width, height] = figures.window;
    println!(
        "  the page (headless Chromium, WebGL2 on SwiftShader, a {width}x{height} window): {} arrow-key moves, \
         each until its full stage was drawn; ms from the move's sending to the stage first drawn, and the same \
         less the move's draw (the page's draw of its preview)",
        figures.key_moves
    );
    let ms = |s: Option<f64>| s.map_or("-".to_owned(), |s| format!("{s:.0}"));
    println!(
        "  {:<8} {:>6} {:>10} {:>8} {:>16} {:>14}",
        "stage", "drawn", "median ms", "p90 ms", "less draw median", "less draw p90"
    );
    for stage in &figures.stages {
        println!(
            "  {:<8} {:>6} {:>10} {:>8} {:>16} {:>14}",
            stage.quality,
            stage.drawn,
            ms(stage.since_sent_ms.map(|s| s.median)),
            ms(stage.since_sent_ms.map(|s| s.p90)),
            ms(stage.less_draw_ms.map(|s| s.median)),
            ms(stage.less_draw_ms.map(|s| s.p90)),
        );
    }
    println!(
        "  draw: median {} ms, p90 {} ms",
        ms(figures.draw_ms.map(|s| s.median)),
        ms(figures.draw_ms.map(|s| s.p90))
    );
    let d = &figures.drag;
    println!(
        "  drag: {} mouse moves in {:.2} s; {} moves sent, {} previews drawn, {:.1} previews a second",
        d.mouse_moves, d.seconds, d.moves_sent, d.previews_drawn, d.previews_per_second
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The figures of a fixed `viewTimings`: each stage less its move's
    /// sending, and less its `draw` too; null stages and null draws left
    /// out of the figures they miss; medians of what is left.
    #[test]
    fn the_page_figures_subtract_each_moves_sending_and_draw_and_skip_nulls() {
        let timings: Vec<ViewTiming> = serde_json::from_str(
            r#"[
                {"sent": 1000, "preview": 1040, "refine": 1100, "full": 1300, "draw": 10},
                {"sent": 2000, "preview": 2060, "refine": null, "full": 2250, "draw": 20},
                {"sent": 3000, "preview": 3030, "refine": 3090, "full": 3400, "draw": null},
                {"sent": 4000, "preview": null, "refine": null, "full": null, "draw": null}
            ]"#,
        )
        .unwrap();
        let stages = stage_figures(&timings);
        let spread = |median, p90| Some(Spread { median, p90 });
        // preview: 40, 60, 30 after sending; less draw 30, 40 (the third has no draw).
        assert_eq!(
            stages[0],
            StageFigures {
                quality: "preview",
                drawn: 3,
                since_sent_ms: spread(40.0, 60.0),
                less_draw_ms: spread(35.0, 40.0),
            }
        );
        // refine: 100 and 90; less draw 90 only.
        assert_eq!(stages[1].drawn, 2);
        assert_eq!(stages[1].since_sent_ms, spread(95.0, 100.0));
        assert_eq!(stages[1].less_draw_ms, spread(90.0, 90.0));
        // full: 300, 250, 400; less draw 290, 230.
        assert_eq!(stages[2].quality, "full");
        assert_eq!(stages[2].since_sent_ms, spread(300.0, 400.0));
        assert_eq!(stages[2].less_draw_ms, spread(260.0, 290.0));

        let none = stage_figures(&timings[3..]);
        assert!(
            none.iter()
                .all(|s| s.drawn == 0 && s.since_sent_ms.is_none() && s.less_draw_ms.is_none())
        );
    }

    /// A drag counts the moves sent and the previews drawn (of any move)
    /// within it, its bounds included, and the previews' rate.
    #[test]
    fn a_drag_counts_the_moves_sent_and_the_previews_drawn_within_it() {
        let timings: Vec<ViewTiming> = serde_json::from_value(json!([
            // Before the drag: neither counts.
            {"sent": 100, "preview": 150, "refine": 200, "full": 400, "draw": 5},
            // Sent at the press, drawn within.
            {"sent": 1000, "preview": 1100, "refine": null, "full": null, "draw": 5},
            {"sent": 1100, "preview": null, "refine": null, "full": null, "draw": null},
            {"sent": 1500, "preview": 1600, "refine": null, "full": null, "draw": 6},
            // Sent within, its preview at the release.
            {"sent": 2900, "preview": 3000, "refine": 3100, "full": 3300, "draw": 5},
            // Sent after the release.
            {"sent": 3050, "preview": 3100, "refine": 3200, "full": 3500, "draw": 5},
        ]))
        .unwrap();
        let drag = drag_figures(&timings, 1000.0, 3000.0, 60);
        assert_eq!(
            drag,
            DragFigures {
                seconds: 2.0,
                mouse_moves: 60,
                moves_sent: 4,
                previews_drawn: 3,
                previews_per_second: 1.5,
            }
        );
        assert_eq!(drag_figures(&[], 5.0, 5.0, 0).previews_per_second, 0.0);
    }
}
