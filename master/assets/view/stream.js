// The view's stage messages (docs/http-api.md, "The view's stage messages"):
// the decoder, and the stream that follows GET /view/stream.

const HEADER_BYTES = 28;
const QUALITIES = ["preview", "refine", "full"];

// Decodes one message (an ArrayBuffer holding exactly it).
export function decodeStage(buffer) {
  const view = new DataView(buffer);
  const magic = String.fromCharCode(...new Uint8Array(buffer, 0, 4));
  if (magic !== "VTVS") throw new Error("not a stage message");
  if (view.getUint8(4) !== 2) throw new Error("stage message version " + view.getUint8(4));
  const kind = view.getUint8(5);
  const header = {
    quality: QUALITIES[view.getUint8(6)],
    generation: Number(view.getBigUint64(8, true)),
    eye: [0, 1, 2].map((k) => view.getFloat32(16 + 4 * k, true)),
  };
  // Plane of `count` items of `size` floats or u32s from byte `at`, copied
  // so that it starts aligned.
  const floats = (at, count) => new Float32Array(buffer.slice(at, at + count * 4));
  const words = (at, count) => new Uint32Array(buffer.slice(at, at + count * 4));
  if (kind === 1) {
    const vertices = view.getUint32(HEADER_BYTES, true);
    const faces = view.getUint32(HEADER_BYTES + 4, true);
    let at = HEADER_BYTES + 8;
    const plane = () => { const p = floats(at, vertices * 3); at += vertices * 12; return p; };
    const positions = plane();
    const colors = plane();
    const reflected = plane();
    const transmitted = plane();
    const objects = words(at, vertices);
    at += vertices * 4;
    const behind = plane();
    const reflectionScale = floats(at, vertices);
    at += vertices * 4;
    const indices = words(at, faces * 3);
    at += faces * 12;
    if (at !== buffer.byteLength) throw new Error("a mesh message of the wrong length");
    return {
      kind: "mesh", ...header, positions, colors, reflected, transmitted, objects,
      behind, reflectionScale, faces: indices,
    };
  }
  if (kind === 2) {
    const [frameWidth, frameHeight, x0, y0, width, height] =
      [0, 1, 2, 3, 4, 5].map((k) => view.getUint32(HEADER_BYTES + 4 * k, true));
    let at = HEADER_BYTES + 24;
    const bits = new Uint8Array(buffer, at, Math.ceil((width * height) / 8));
    at += bits.length;
    const mask = new Uint8Array(width * height);
    let covered = 0;
    for (let i = 0; i < mask.length; i++) {
      mask[i] = (bits[i >> 3] >> (i & 7)) & 1;
      covered += mask[i];
    }
    const colors = floats(at, covered * 3);
    at += covered * 12;
    if (at !== buffer.byteLength) throw new Error("an overlay message of the wrong length");
    return { kind: "overlay", ...header, frameWidth, frameHeight, x0, y0, width, height, mask, colors };
  }
  throw new Error("unknown stage message kind " + kind);
}

// Follows GET /view/stream, calling onStage(decoded) for each message as it
// comes; opens it again when it ends (the master restarted), a second later.
export function followStages(onStage) {
  let pending = new Uint8Array(0);
  const take = (chunk) => {
    const joined = new Uint8Array(pending.length + chunk.length);
    joined.set(pending);
    joined.set(chunk, pending.length);
    let at = 0;
    while (joined.length - at >= 4) {
      const length = new DataView(joined.buffer, at, 4).getUint32(0, true);
      if (joined.length - at - 4 < length) break;
      const message = joined.slice(at + 4, at + 4 + length).buffer;
      at += 4 + length;
      onStage(decodeStage(message));
    }
    pending = joined.slice(at);
  };
  const open = async () => {
    pending = new Uint8Array(0);
    try {
      const reply = await fetch("/view/stream", { cache: "no-store" });
      const reader = reply.body.getReader();
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        take(value);
      }
    } catch (e) {
      console.warn("view stream: " + e);
    }
    setTimeout(open, 1000);
  };
  open();
}

// Linear light to 8-bit sRGB by the CPU's formula (vtfarm_imaging: f32
// arithmetic, truncating after + 0.5).
const f = Math.fround;
const INVERSE_GAMMA = f(1 / f(2.4));
export function srgb8Formula(linear) {
  const c = f(Math.min(1, Math.max(0, linear)));
  const s = c <= f(0.0031308)
    ? f(c * f(12.92))
    : f(f(f(1.055) * f(Math.pow(c, INVERSE_GAMMA))) - f(0.055));
  return Math.floor(f(f(s * 255) + 0.5));
}

// The formula rises with its input: per output k, the smallest f32 that
// gives k, found once by bisection over the f32s' bit patterns in [0, 1].
const SRGB8_STEPS = (() => {
  const bits = new Uint32Array(1);
  const float = new Float32Array(bits.buffer);
  const at = (b) => { bits[0] = b; return float[0]; };
  const steps = new Float32Array(256);
  for (let k = 1; k < 256; k++) {
    let [lo, hi] = [0, 0x3f800000];
    while (lo < hi) {
      const mid = Math.floor((lo + hi) / 2);
      if (srgb8Formula(at(mid)) >= k) hi = mid; else lo = mid + 1;
    }
    steps[k] = at(lo);
  }
  return steps;
})();

// Linear light to 8-bit sRGB as the CPU's images are written
// (srgb8Formula, by its table: a frame's overlay converts hundreds of
// thousands of values, and a search of 256 steps is far cheaper than pow).
export function srgb8(linear) {
  const c = f(Math.min(1, Math.max(0, linear)));
  let [lo, hi] = [0, 255];
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (c >= SRGB8_STEPS[mid]) lo = mid; else hi = mid - 1;
  }
  return lo;
}
