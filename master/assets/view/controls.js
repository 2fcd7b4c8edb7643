// The view's controls: the eye moves continuously (arrow keys and PgUp/PgDn
// 1 cm, a drag 1 mm a pixel) within the box around the source job's eye;
// each move is drawn from the scene the page holds (onEye) and sent to
// POST /api/view, one at a time (a move made while one is on its way goes
// when it returns, the newest only); a dragging hand's moves ask for their
// preview only, and the eye where the drag ends is sent again for every
// stage. Each move sent gets its timings in
// window.vtfarm.viewTimings: {sent, preview, refine, full} as
// performance.now() when it was sent and when each stage was first drawn,
// draw as how long the draw that first showed its preview took; null for
// a stage never drawn.

// Tells the page's watchers (its tests) that the view's state changed: a
// move was sent, a stage came or was drawn.
export function viewChanged() {
  document.dispatchEvent(new CustomEvent("vtfarm-view-changed"));
}

const KEYS = {
  ArrowLeft: [-0.01, 0, 0], ArrowRight: [0.01, 0, 0], ArrowUp: [0, 0.01, 0],
  ArrowDown: [0, -0.01, 0], PageUp: [0, 0, 0.01], PageDown: [0, 0, -0.01],
};

export class ViewControls {
  // source(): the chosen job or null; onEye(offset): the eye moved.
  constructor({ surface, eyeBox, source, onEye }) {
    this.eyeBox = eyeBox;
    this.source = source;
    this.onEye = onEye;
    this.offset = [0, 0, 0];
    this.sending = false;
    this.pending = false;
    // Whether the last move sent asked for its preview only.
    this.previewOnlySent = false;
    // Moves by generation (the master's number for them).
    this.moves = new Map();
    // Stages drawn before their move's reply came: generation -> [quality, now, took].
    this.early = new Map();
    window.vtfarm = window.vtfarm || {};
    window.vtfarm.viewTimings = [];
    document.addEventListener("keydown", (e) => {
      if (e.target.tagName === "SELECT" || e.target.tagName === "INPUT" || this.source() === null) return;
      if (e.key === "0") { this.reset(); e.preventDefault(); return; }
      const delta = KEYS[e.key];
      if (delta) { this.move(delta); e.preventDefault(); }
    });
    // Where the pointer was last while it drags the eye.
    this.from = null;
    surface.addEventListener("pointerdown", (e) => {
      this.from = [e.clientX, e.clientY];
      surface.setPointerCapture(e.pointerId);
    });
    surface.addEventListener("pointermove", (e) => {
      if (!this.from || this.source() === null) return;
      const d = [e.clientX - this.from[0], e.clientY - this.from[1]];
      this.from = [e.clientX, e.clientY];
      this.move([d[0] * 0.001, -d[1] * 0.001, 0]);
    });
    surface.addEventListener("pointerup", () => {
      this.from = null;
      // The eye where the drag ended is drawn whole, and (its moves having
      // asked for previews only) sent again for all its stages.
      this.onEye(this.offset);
      if (this.previewOnlySent) this.send();
    });
  }

  // Whether the eye is being dragged.
  get dragging() {
    return this.from !== null;
  }

  move(delta) {
    const box = this.eyeBox;
    this.set(this.offset.map((v, k) => Math.max(-box, Math.min(box, v + delta[k]))));
  }

  reset() {
    this.set([0, 0, 0]);
  }

  set(offset) {
    this.offset = offset;
    this.onEye(offset);
    this.send();
  }

  async send() {
    if (this.source() === null) return;
    if (this.sending) { this.pending = true; return; }
    this.sending = true;
    const timing = { sent: performance.now(), preview: null, refine: null, full: null, draw: null };
    this.previewOnlySent = this.dragging;
    try {
      const reply = await fetch("/api/view", {
        method: "POST",
        headers: { "content-type": "application/json" },
        // This page draws the scene: the master's base frame is needed only
        // where the packages look. A dragging hand sees previews only: the
        // farm traces no more of its moves.
        body: JSON.stringify({
          job: this.source(), offset: this.offset, page_draws_scene: true, preview_only: this.dragging,
        }),
      });
      if (reply.ok) {
        const { generation } = await reply.json();
        window.vtfarm.viewTimings.push(timing);
        viewChanged();
        if (generation != null) {
          this.moves.set(generation, timing);
          for (const [quality, now, took] of this.early.get(generation) || []) {
            this.drawn(generation, quality, now, took);
          }
          this.early.delete(generation);
        }
      }
    } finally {
      this.sending = false;
      if (this.pending) { this.pending = false; this.send(); }
    }
  }

  // Whether a stage of move `generation` may be shown: no newer move was
  // sent (the stream may still deliver an outdated move's stage).
  current(generation) {
    for (const g of this.moves.keys()) if (g > generation) return false;
    return true;
  }

  // A stage of move `generation` was drawn at `now`, the draw taking `took` ms.
  drawn(generation, quality, now, took) {
    const timing = this.moves.get(generation);
    if (!timing) {
      if (this.sending) this.early.set(generation, [...(this.early.get(generation) || []), [quality, now, took]]);
      return;
    }
    if (timing[quality] !== null) return;
    timing[quality] = now;
    if (quality === "preview") timing.draw = took;
    viewChanged();
  }
}
