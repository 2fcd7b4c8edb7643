// The view's scene renderer (WebGL2, three.js): the source job's scene from
// the current eye, shaded as the CPU rasterizer shades it (Phong with the
// scene's exact Ka, Kd, Ks and shininess, no distance falloff, two-sided),
// the reflector drawn from the stage meshes' vertex colours over what lies
// behind it, and the `full` stage's pixels while the eye stays.
//
// Three passes: the opaque scene (the reflectors left out) into two linear
// float targets with their depth, unshadowed and shadowed (the lights'
// shadow maps are drawn once, when the scene is loaded); the first to the
// canvas in 8-bit sRGB with its depth; then the reflector mesh,
// depth-tested, each fragment the Gouraud-interpolated vertex colour and
// ghost plus the glass's weight times the shadowed target's colour there
// (the paper's stencil and z-buffer blend), in linear light before the one
// sRGB conversion.

import * as THREE from "three";
import { srgb8 } from "./stream.js";

const MAX_LIGHTS = 8;

const SRGB_GLSL = `
vec3 toSrgb(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}`;

// vtfarm_raster's Phong, per fragment in world space, into two targets:
// unshadowed, as the CPU's base frame draws the scene, and shadowed by the
// lights' shadow maps (`shadows`, from shadowMaps), as the CPU's
// thin-glass pass shades what the glass shows behind it.
function phongMaterial(exact, setup, shadows) {
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
    shadowBias: { value: setup.shadows.bias },
  };
  // Each mapped light's test, written out with its own sampler (a
  // sampler array takes constant indices only).
  const tests = lights.map((_, i) => {
    const map = shadows[i];
    if (!map) return `bool lit${i}(vec3 p) { return true; }`;
    uniforms["shadowMap" + i] = { value: map.target.texture };
    uniforms["shadowMatrix" + i] = { value: map.matrix };
    uniforms["shadowEye" + i] = { value: map.eye };
    uniforms["shadowForward" + i] = { value: map.forward };
    return `
      uniform sampler2D shadowMap${i};
      uniform mat4 shadowMatrix${i};
      uniform vec3 shadowEye${i}, shadowForward${i};
      bool lit${i}(vec3 p) {
        float depth = dot(p - shadowEye${i}, shadowForward${i});
        vec4 c = shadowMatrix${i} * vec4(p, 1.0);
        if (depth < 1e-3 || c.w <= 0.0) return true;
        int size = textureSize(shadowMap${i}, 0).x;
        ivec2 texel = ivec2(floor((c.xy / c.w * 0.5 + 0.5) * float(size)));
        if (texel.x < 0 || texel.y < 0 || texel.x >= size || texel.y >= size) return true;
        float seen = texelFetch(shadowMap${i}, texel, 0).r;
        return seen <= 0.0 || seen >= depth - shadowBias;
      }`;
  });
  const lightTerms = lights.map((_, i) => `
        {
          vec3 toLight = lightPoint[${i}] > 0.5
            ? normalize(lightVector[${i}] - worldPosition) : normalize(-lightVector[${i}]);
          float nDotL = dot(n, toLight);
          if (nDotL > 0.0) {
            vec3 term = diffuse * nDotL;
            if (max(specular.r, max(specular.g, specular.b)) > 0.0) {
              vec3 r = n * (2.0 * nDotL) - toLight;
              term += specular * pow(max(dot(r, toEye), 0.0), shininess);
            }
            color += term * lightRadiance[${i}];
            if (lit${i}(worldPosition)) shadowed += term * lightRadiance[${i}];
          }
        }`).join("");
  return new THREE.ShaderMaterial({
    uniforms,
    glslVersion: THREE.GLSL3,
    side: THREE.DoubleSide,
    defines: { LIGHTS: Math.max(lights.length, 1) },
    vertexShader: `
      out vec3 worldPosition;
      out vec3 worldNormal;
      void main() {
        vec4 w = modelMatrix * vec4(position, 1.0);
        worldPosition = w.xyz;
        worldNormal = mat3(modelMatrix) * normal;
        gl_Position = projectionMatrix * viewMatrix * w;
      }`,
    fragmentShader: `
      layout(location = 0) out highp vec4 baseColor;
      layout(location = 1) out highp vec4 shadowedColor;
      uniform vec3 unlit, diffuse, specular, eye;
      uniform float shininess, shadowBias;
      uniform vec3 lightVector[LIGHTS];
      uniform float lightPoint[LIGHTS];
      uniform vec3 lightRadiance[LIGHTS];
      in vec3 worldPosition;
      in vec3 worldNormal;
      ${tests.join("\n")}
      void main() {
        vec3 toEye = normalize(eye - worldPosition);
        vec3 n = normalize(worldNormal);
        if (dot(n, toEye) < 0.0) n = -n;
        vec3 color = unlit;
        vec3 shadowed = unlit;
        ${lightTerms}
        baseColor = vec4(color, 1.0);
        shadowedColor = vec4(shadowed, 1.0);
      }`,
  });
}

// The lights' shadow maps (setup.shadows, the CPU thin-glass pass's own
// views): per light, the view depth of the nearest surface that casts a
// shadow, per texel, or null for a light that is never shadowed. Drawn
// once: they depend on the lights and the scene, not on the eye.
function shadowMaps(renderer, casters, shadows) {
  const depth = new THREE.ShaderMaterial({
    side: THREE.DoubleSide,
    uniforms: { from: { value: new THREE.Vector3() }, forward: { value: new THREE.Vector3() } },
    vertexShader: `
      varying vec3 worldPosition;
      void main() {
        vec4 w = modelMatrix * vec4(position, 1.0);
        worldPosition = w.xyz;
        gl_Position = projectionMatrix * viewMatrix * w;
      }`,
    fragmentShader: `
      uniform vec3 from, forward;
      varying vec3 worldPosition;
      void main() { gl_FragColor = vec4(dot(worldPosition - from, forward), 0.0, 0.0, 1.0); }`,
  });
  casters.overrideMaterial = depth;
  const maps = shadows.cameras.map((view) => {
    if (!view) return null;
    const eye = new THREE.Vector3(...view.eye);
    const target = new THREE.Vector3(...view.target);
    const distance = eye.distanceTo(target);
    const radius = distance * Math.sin(THREE.MathUtils.degToRad(view.fov_y_deg / 2));
    const camera = new THREE.PerspectiveCamera(view.fov_y_deg, 1, distance * 0.01, distance + 2 * radius);
    camera.up.set(...view.up);
    camera.position.copy(eye);
    camera.lookAt(target);
    camera.updateMatrixWorld();
    const map = new THREE.WebGLRenderTarget(shadows.size, shadows.size, {
      type: THREE.FloatType,
      format: THREE.RedFormat,
      minFilter: THREE.NearestFilter,
      magFilter: THREE.NearestFilter,
    });
    depth.uniforms.from.value.copy(eye);
    const forward = target.clone().sub(eye).normalize();
    depth.uniforms.forward.value.copy(forward);
    renderer.setRenderTarget(map);
    // Nothing there (depth 0, nearer than any surface's): lit.
    renderer.setClearColor(new THREE.Color(0, 0, 0), 1);
    renderer.clear();
    renderer.render(casters, camera);
    const matrix = new THREE.Matrix4().multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse);
    return { target: map, matrix, eye, forward };
  });
  renderer.setRenderTarget(null);
  return maps;
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

// The reflector, as the CPU's thin-glass pass finishes a pixel
// (vtfarm_vertex's `Behind`): the traced colour, the back surface's ghost
// (the reflected part times the reflection's scale less one) and what the
// glass lets through of the scene behind it, every term Gouraud-shaded
// from the stage's vertices.
function glassMaterial(target) {
  // The drawing's size, to find each fragment's pixel in `behind`.
  const size = new THREE.Vector2(target.width, target.height);
  return new THREE.ShaderMaterial({
    uniforms: {
      behindScene: { value: target.textures[1] },
      size: { value: size },
    },
    side: THREE.DoubleSide,
    vertexColors: true,
    vertexShader: `
      attribute vec3 reflected;
      attribute vec3 behind;
      attribute float reflectionScale;
      varying vec3 traced;
      varying vec3 ghost;
      varying vec3 letThrough;
      void main() {
        traced = color;
        ghost = reflected * (reflectionScale - 1.0);
        letThrough = behind;
        gl_Position = projectionMatrix * viewMatrix * vec4(position, 1.0);
      }`,
    fragmentShader: `
      uniform sampler2D behindScene;
      uniform vec2 size;
      varying vec3 traced;
      varying vec3 ghost;
      varying vec3 letThrough;
      ${SRGB_GLSL}
      void main() {
        vec3 back = texture2D(behindScene, gl_FragCoord.xy / size).rgb;
        gl_FragColor = vec4(toSrgb(traced + ghost + letThrough * back), 1.0);
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
    // The scene as the base frame draws it, and shadowed as the glass
    // shows it (phongMaterial).
    const target = (w, h) => new THREE.WebGLRenderTarget(w, h, {
      count: 2,
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
    const behind = [];
    const casters = new THREE.Scene();
    for (const mesh of meshes) {
      mesh.updateWorldMatrix(true, false);
      // The GLB's materials are the scene's, in order.
      const association = gltf.parser.associations.get(mesh.material);
      const index = association ? association.materials : undefined;
      if (index === undefined || setup.shadow_casting[index]) casters.add(mesh.clone());
      // The GLB names each mesh's node after its scene object.
      const name = mesh.name || (mesh.parent && mesh.parent.name);
      if (reflectors.has(name)) continue;
      const exact = mesh.material.userData && mesh.material.userData.vtfarm;
      if (!exact) continue;
      if (Math.max(...exact.transmittance) > 0) continue; // other glass: not behind
      behind.push([mesh, exact]);
    }
    const shadows = shadowMaps(renderer, casters, setup.shadows);
    for (const [mesh, exact] of behind) {
      const drawn = mesh.clone();
      drawn.material = phongMaterial(exact, setup, shadows);
      this.phong.push(drawn.material);
      this.opaque.add(drawn);
    }
    this.present = new THREE.Scene();
    this.presentMaterial = presentMaterial(this.target);
    this.present.add(new THREE.Mesh(new THREE.PlaneGeometry(2, 2), this.presentMaterial));
    this.screen = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
    this.glass = new THREE.Scene();
    this.glassMaterial = glassMaterial(this.target);
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
    geometry.setAttribute("reflected", new THREE.BufferAttribute(stage.reflected, 3));
    geometry.setAttribute("behind", new THREE.BufferAttribute(stage.behind, 3));
    geometry.setAttribute("reflectionScale", new THREE.BufferAttribute(stage.reflectionScale, 1));
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

  // No `full` overlay until the next.
  clearOverlay() {
    this.overlayScene.clear();
    this.overlay = null;
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
    this.glassMaterial.uniforms.behindScene.value = target.textures[1];
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
