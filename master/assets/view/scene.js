// The view's scene renderer (WebGL2, three.js): the source job's scene from
// the current eye, shaded as the CPU rasterizer shades it (Phong with the
// scene's exact Ka, Kd, Ks and shininess, no distance falloff, two-sided),
// the reflector drawn from the stage meshes' vertex colours over what lies
// behind it, and the `full` stage's pixels while the eye stays.
//
// Three passes: the opaque scene (the reflectors left out) into a linear
// float target with its depth; that target to the canvas in 8-bit sRGB with
// its depth; then the reflector mesh, depth-tested, each fragment the
// Gouraud-interpolated vertex colour plus the glass's transmittance times
// the target's colour there (the paper's stencil and z-buffer blend), in
// linear light before the one sRGB conversion.

import * as THREE from "three";
import { srgb8 } from "./stream.js";

const MAX_LIGHTS = 8;

const SRGB_GLSL = `
vec3 toSrgb(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}`;

// vtfarm_raster's Phong, per fragment in world space.
function phongMaterial(exact, setup) {
  const lights = setup.lights.slice(0, MAX_LIGHTS);
  const vec = (a) => new THREE.Vector3(a[0], a[1], a[2]);
  const uniforms = {
    unlit: { value: vec(exact.emission).add(vec(exact.ambient).multiply(vec(setup.ambient))) },
    diffuse: { value: vec(exact.diffuse) },
    specular: { value: vec(exact.specular) },
    shininess: { value: Math.max(exact.shininess, 1) },
    eye: { value: new THREE.Vector3() },
    lightVector: { value: lights.map((l) => vec(l.vector)) },
    lightPoint: { value: lights.map((l) => (l.kind === "point" ? 1 : 0)) },
    lightRadiance: { value: lights.map((l) => vec(l.radiance)) },
  };
  return new THREE.ShaderMaterial({
    uniforms,
    side: THREE.DoubleSide,
    defines: { LIGHTS: Math.max(lights.length, 1), USED_LIGHTS: lights.length },
    vertexShader: `
      varying vec3 worldPosition;
      varying vec3 worldNormal;
      void main() {
        vec4 w = modelMatrix * vec4(position, 1.0);
        worldPosition = w.xyz;
        worldNormal = mat3(modelMatrix) * normal;
        gl_Position = projectionMatrix * viewMatrix * w;
      }`,
    fragmentShader: `
      uniform vec3 unlit, diffuse, specular, eye;
      uniform float shininess;
      uniform vec3 lightVector[LIGHTS];
      uniform float lightPoint[LIGHTS];
      uniform vec3 lightRadiance[LIGHTS];
      varying vec3 worldPosition;
      varying vec3 worldNormal;
      void main() {
        vec3 toEye = normalize(eye - worldPosition);
        vec3 n = normalize(worldNormal);
        if (dot(n, toEye) < 0.0) n = -n;
        vec3 color = unlit;
        for (int i = 0; i < USED_LIGHTS; i++) {
          vec3 toLight = lightPoint[i] > 0.5
            ? normalize(lightVector[i] - worldPosition) : normalize(-lightVector[i]);
          float nDotL = dot(n, toLight);
          if (nDotL <= 0.0) continue;
          vec3 term = diffuse * nDotL;
          if (max(specular.r, max(specular.g, specular.b)) > 0.0) {
            vec3 r = n * (2.0 * nDotL) - toLight;
            term += specular * pow(max(dot(r, toEye), 0.0), shininess);
          }
          color += term * lightRadiance[i];
        }
        gl_FragColor = vec4(color, 1.0);
      }`,
  });
}

// A full-screen pass: the linear target to sRGB, with its depth.
function presentMaterial(target) {
  return new THREE.ShaderMaterial({
    uniforms: { color: { value: target.texture }, depth: { value: target.depthTexture } },
    // Depth writes need the test on: it always passes.
    depthTest: true,
    depthFunc: THREE.AlwaysDepth,
    depthWrite: true,
    vertexShader: `varying vec2 uv0; void main() { uv0 = uv; gl_Position = vec4(position.xy, 0.0, 1.0); }`,
    fragmentShader: `
      uniform sampler2D color, depth;
      varying vec2 uv0;
      ${SRGB_GLSL}
      void main() {
        gl_FragColor = vec4(toSrgb(texture2D(color, uv0).rgb), 1.0);
        gl_FragDepth = texture2D(depth, uv0).r;
      }`,
  });
}

// The reflector: vertex colours plus transmittance times what lies behind.
function glassMaterial(target, transmittance) {
  // The drawing's size, to find each fragment's pixel in `behind`.
  const size = new THREE.Vector2(target.width, target.height);
  return new THREE.ShaderMaterial({
    uniforms: {
      behind: { value: target.texture },
      size: { value: size },
      transmittance: { value: new THREE.Vector3(...transmittance) },
    },
    side: THREE.DoubleSide,
    vertexColors: true,
    vertexShader: `
      varying vec3 traced;
      void main() { traced = color; gl_Position = projectionMatrix * viewMatrix * vec4(position, 1.0); }`,
    fragmentShader: `
      uniform sampler2D behind;
      uniform vec2 size;
      uniform vec3 transmittance;
      varying vec3 traced;
      ${SRGB_GLSL}
      void main() {
        vec3 back = texture2D(behind, gl_FragCoord.xy / size).rgb;
        gl_FragColor = vec4(toSrgb(traced + transmittance * back), 1.0);
      }`,
  });
}

// The smallest rectangle holding both.
function union(a, b) {
  if (a.w === 0 || a.h === 0) return b;
  if (b.w === 0 || b.h === 0) return a;
  const x = Math.min(a.x, b.x);
  const y = Math.min(a.y, b.y);
  return { x, y, w: Math.max(a.x + a.w, b.x + b.w) - x, h: Math.max(a.y + a.h, b.y + b.h) - y };
}

export class SceneView {
  // canvas: the page's; setup: /view/setup.json; gltf: the loaded scene;
  // shownWidth: the device pixels the canvas is shown at. It is drawn at
  // the job's size, or smaller to fit shownWidth: pixels never shown cost
  // a draw as much as those shown.
  constructor(canvas, setup, gltf, shownWidth) {
    this.setup = setup;
    this.canvas = canvas;
    const scale = Math.min(1, shownWidth / setup.width);
    const width = Math.max(1, Math.round(setup.width * scale));
    const height = Math.max(1, Math.round(setup.height * scale));
    canvas.width = width;
    canvas.height = height;
    // Shown at this size whatever it is drawn at (a drag draws it coarser).
    canvas.style.width = width / (window.devicePixelRatio || 1) + "px";
    const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
    renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
    renderer.setPixelRatio(1);
    renderer.setSize(width, height, false);
    renderer.autoClear = false;
    this.renderer = renderer;
    const target = (w, h) => new THREE.WebGLRenderTarget(w, h, {
      type: THREE.FloatType,
      minFilter: THREE.NearestFilter,
      magFilter: THREE.NearestFilter,
      depthTexture: new THREE.DepthTexture(w, h, THREE.FloatType),
    });
    this.target = target(width, height);
    // The view while the eye is dragged: a quarter of the pixels, so a
    // slow rasterizer keeps up with the hand; the eye where the drag ends
    // is drawn whole.
    this.coarseTarget = target(Math.max(1, Math.round(width / 2)), Math.max(1, Math.round(height / 2)));
    this.camera = new THREE.PerspectiveCamera(setup.fov_y_deg, setup.width / setup.height, 0.01, 1000);
    this.camera.up.set(...setup.up);
    this.opaque = new THREE.Scene();
    this.background = new THREE.Color(...setup.background);
    this.phong = [];
    const reflectors = new Set(setup.reflector_objects);
    const meshes = [];
    gltf.scene.traverse((o) => { if (o.isMesh) meshes.push(o); });
    for (const mesh of meshes) {
      // The GLB names each mesh's node after its scene object.
      const name = mesh.name || (mesh.parent && mesh.parent.name);
      if (reflectors.has(name)) continue;
      const exact = mesh.material.userData && mesh.material.userData.vtfarm;
      if (!exact) continue;
      if (Math.max(...exact.transmittance) > 0) continue; // other glass: not behind
      mesh.material = phongMaterial(exact, setup);
      this.phong.push(mesh.material);
      mesh.updateWorldMatrix(true, false);
      this.opaque.add(mesh.clone());
    }
    this.present = new THREE.Scene();
    this.presentMaterial = presentMaterial(this.target);
    this.present.add(new THREE.Mesh(new THREE.PlaneGeometry(2, 2), this.presentMaterial));
    this.screen = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
    this.glass = new THREE.Scene();
    this.glassMaterial = glassMaterial(this.target, setup.transmittance);
    this.overlayScene = new THREE.Scene();
    this.overlay = null;
    this.offset = [0, 0, 0];
    // The eye the target's opaque scene was drawn from.
    this.opaqueEye = null;
    this.drawnCoarse = false;
    // Where the glass was drawn last, to redraw only there while the eye stays.
    this.shownGlass = null;
  }

  // The eye at `offset` (metres) from the source job's eye.
  setOffset(offset) {
    this.offset = offset.slice();
  }

  eye() {
    return this.setup.eye.map((v, k) => Math.fround(v + this.offset[k]));
  }

  // A `preview` or `refine` message: the reflector mesh from now on.
  setMesh(stage) {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(stage.positions, 3));
    geometry.setAttribute("color", new THREE.BufferAttribute(stage.colors, 3));
    geometry.setIndex(new THREE.BufferAttribute(stage.faces, 1));
    this.glass.clear();
    const mesh = new THREE.Mesh(geometry, this.glassMaterial);
    mesh.frustumCulled = false;
    this.glass.add(mesh);
  }

  // A `full` message: its pixels, drawn while the eye is where they were traced.
  setOverlay(stage) {
    const { width, height } = stage;
    const rgba = new Uint8Array(width * height * 4);
    let k = 0;
    for (let i = 0; i < stage.mask.length; i++) {
      if (!stage.mask[i]) continue;
      // Rows go up in the texture: the message's rows go down the frame.
      const row = height - 1 - Math.floor(i / width);
      const at = (row * width + (i % width)) * 4;
      for (let c = 0; c < 3; c++) rgba[at + c] = srgb8(stage.colors[k * 3 + c]);
      rgba[at + 3] = 255;
      k++;
    }
    const texture = new THREE.DataTexture(rgba, width, height, THREE.RGBAFormat);
    texture.minFilter = THREE.NearestFilter;
    texture.magFilter = THREE.NearestFilter;
    texture.needsUpdate = true;
    const W = stage.frameWidth;
    const H = stage.frameHeight;
    const plane = new THREE.PlaneGeometry((2 * width) / W, (2 * height) / H);
    const material = new THREE.ShaderMaterial({
      uniforms: { pixels: { value: texture } },
      transparent: true,
      depthTest: false,
      // Placed in clip space by the quad's own position (no camera).
      vertexShader: `varying vec2 uv0; void main() { uv0 = uv; gl_Position = modelMatrix * vec4(position.xy, 0.0, 1.0); }`,
      fragmentShader: `
        uniform sampler2D pixels;
        varying vec2 uv0;
        void main() { vec4 p = texture2D(pixels, uv0); if (p.a < 0.5) discard; gl_FragColor = p; }`,
    });
    const quad = new THREE.Mesh(plane, material);
    quad.position.set(((stage.x0 + width / 2) / W) * 2 - 1, 1 - ((stage.y0 + height / 2) / H) * 2, 0);
    this.overlayScene.clear();
    this.overlayScene.add(quad);
    this.overlay = stage;
  }

  // Whether the overlay was traced from the eye shown now.
  overlayHolds() {
    const eye = this.eye();
    return this.overlay !== null && this.overlay.eye.every((v, k) => Math.abs(v - eye[k]) < 1e-5);
  }

  // The drawing's pixels the glass mesh and the overlay cover, from the
  // bottom left (all of them when a vertex lies behind the eye).
  glassRect(target) {
    const all = { x: 0, y: 0, w: target.width, h: target.height };
    let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
    const p = new THREE.Vector3();
    const inView = new THREE.Vector3();
    for (const mesh of this.glass.children) {
      const positions = mesh.geometry.getAttribute("position");
      for (let i = 0; i < positions.count; i++) {
        p.fromBufferAttribute(positions, i);
        if (inView.copy(p).applyMatrix4(this.camera.matrixWorldInverse).z >= 0) return all;
        p.project(this.camera);
        x0 = Math.min(x0, p.x); x1 = Math.max(x1, p.x);
        y0 = Math.min(y0, p.y); y1 = Math.max(y1, p.y);
      }
    }
    if (this.overlay) {
      const o = this.overlay;
      const ndc = (v, size) => (v / size) * 2 - 1;
      x0 = Math.min(x0, ndc(o.x0, o.frameWidth)); x1 = Math.max(x1, ndc(o.x0 + o.width, o.frameWidth));
      y0 = Math.min(y0, -ndc(o.y0 + o.height, o.frameHeight)); y1 = Math.max(y1, -ndc(o.y0, o.frameHeight));
    }
    if (!(x0 <= x1)) return { x: 0, y: 0, w: 0, h: 0 };
    // A pixel's margin for rounding.
    const px = (v, size) => ((v + 1) / 2) * size;
    const x = Math.max(0, Math.floor(px(x0, target.width)) - 1);
    const y = Math.max(0, Math.floor(px(y0, target.height)) - 1);
    const right = Math.min(target.width, Math.ceil(px(x1, target.width)) + 1);
    const top = Math.min(target.height, Math.ceil(px(y1, target.height)) + 1);
    return { x, y, w: Math.max(0, right - x), h: Math.max(0, top - y) };
  }

  // Draws the view (`coarse`: at a quarter of the pixels, while the eye is
  // dragged); returns how long it took, to a
  // one-pixel read-back (ms).
  draw(coarse = false) {
    const start = performance.now();
    const target = coarse ? this.coarseTarget : this.target;
    if (this.drawnCoarse !== coarse) {
      // The whole drawing at the target's size; the page scales the canvas.
      this.renderer.setSize(target.width, target.height, false);
      this.glassMaterial.uniforms.size.value.set(target.width, target.height);
      this.drawnCoarse = coarse;
    }
    this.presentMaterial.uniforms.color.value = target.texture;
    this.presentMaterial.uniforms.depth.value = target.depthTexture;
    this.glassMaterial.uniforms.behind.value = target.texture;
    const eye = this.eye();
    this.camera.position.set(...eye);
    this.camera.lookAt(...this.setup.target);
    this.camera.updateMatrixWorld();
    for (const m of this.phong) m.uniforms.eye.value.set(...eye);
    const r = this.renderer;
    // The scene behind the glass changes only with the eye: a stage that
    // comes for the same eye redraws the glass over it alone.
    const key = eye.join(",") + (coarse ? "/coarse" : "");
    const sameScene = this.opaqueEye === key;
    if (!sameScene) {
      r.setRenderTarget(target);
      r.setClearColor(this.background, 1);
      r.clear();
      r.render(this.opaque, this.camera);
      this.opaqueEye = key;
    }
    r.setRenderTarget(null);
    // Over the same scene, only where the glass was or is now changes.
    const glass = this.glassRect(target);
    const redrawn = sameScene && this.shownGlass ? union(this.shownGlass, glass) : null;
    this.shownGlass = glass;
    if (redrawn) {
      r.setScissor(redrawn.x, redrawn.y, redrawn.w, redrawn.h);
      r.setScissorTest(true);
    }
    r.clear();
    r.render(this.present, this.screen);
    r.render(this.glass, this.camera);
    if (this.overlayHolds()) r.render(this.overlayScene, this.screen);
    r.setScissorTest(false);
    const gl = r.getContext();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
    return performance.now() - start;
  }
}
