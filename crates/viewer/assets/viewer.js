// The viewer's page: one WebGL2 shaded surface, an orbit camera, ray–triangle picking, and the
// WebSocket protocol of docs/viewer.md. No libraries: this file is compiled into the server.
'use strict';
(() => {
  const $ = (id) => document.getElementById(id);
  const canvas = $('view');
  const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });

  // ---- small vector helpers ----
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => Math.sqrt(dot(a, a));
  const unit = (a) => scale(a, 1 / (norm(a) || 1));

  // ---- what the server told us ----
  let hello = null;      // the hello event
  let mesh = null;       // { n, triangles: Uint32Array, pinned: Uint32Array, rest: Float32Array }
  let positions = null;  // Float32Array(3n), the latest frame
  let normals = null;
  let frameStep = 0;
  let state = null;
  let framesShown = 0;
  const frameTimes = [];
  let meshDirty = false;

  // ---- camera: orbit about a target, about the scene's up (hello's `up`, against gravity) ----
  const camera = { target: [0, 0, 0], yaw: 0.6, pitch: 0.35, distance: 1, fov: Math.PI / 4, radius: 1 };
  // The world frame the orbit turns in: `up`, and e1, e2 across it (x and z for y up).
  let world = { up: [0, 1, 0], e1: [1, 0, 0], e2: [0, 0, 1] };
  function setUp(up) {
    const u = unit(up);
    const a = Math.abs(u[0]) > 0.9 ? [0, 0, 1] : [1, 0, 0];
    const e1 = unit(sub(a, scale(u, dot(a, u))));
    world = { up: u, e1, e2: cross(e1, u) };
  }
  // a·e1 + b·up + c·e2.
  const inWorld = (a, b, c) => add(add(scale(world.e1, a), scale(world.up, b)), scale(world.e2, c));
  function basis() {
    const c = Math.cos(camera.pitch);
    const offset = inWorld(c * Math.sin(camera.yaw), Math.sin(camera.pitch), c * Math.cos(camera.yaw));
    const eye = add(camera.target, scale(offset, camera.distance));
    const forward = unit(sub(camera.target, eye));
    const right = unit(cross(forward, world.up));
    const up = cross(right, forward);
    return { eye, forward, right, up };
  }
  function aspect() { return canvas.clientWidth / Math.max(1, canvas.clientHeight); }
  function viewProjection() {
    const { eye, forward: f, right: r, up: u } = basis();
    const view = [r[0], u[0], -f[0], 0, r[1], u[1], -f[1], 0, r[2], u[2], -f[2], 0,
      -dot(r, eye), -dot(u, eye), dot(f, eye), 1];
    const near = camera.distance * 0.01, far = camera.distance * 10 + camera.radius * 4;
    const t = 1 / Math.tan(camera.fov / 2);
    const proj = [t / aspect(), 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1,
      0, 0, (2 * far * near) / (near - far), 0];
    const out = new Float32Array(16);
    for (let c = 0; c < 4; c++) {
      for (let r2 = 0; r2 < 4; r2++) {
        let s = 0;
        for (let k = 0; k < 4; k++) s += proj[k * 4 + r2] * view[c * 4 + k];
        out[c * 4 + r2] = s;
      }
    }
    return out;
  }
  // The ray through a point of the canvas (CSS pixels).
  function ray(x, y) {
    const { eye, forward, right, up } = basis();
    const t = Math.tan(camera.fov / 2);
    const nx = (2 * x) / canvas.clientWidth - 1, ny = 1 - (2 * y) / canvas.clientHeight;
    const dir = unit(add(forward, add(scale(right, nx * t * aspect()), scale(up, ny * t))));
    return { origin: eye, dir };
  }
  // A world point's canvas position (CSS pixels) and depth along the view.
  function project(p) {
    const { eye, forward, right, up } = basis();
    const d = sub(p, eye);
    const z = dot(d, forward), t = Math.tan(camera.fov / 2);
    const nx = dot(d, right) / (z * t * aspect()), ny = dot(d, up) / (z * t);
    return { x: ((nx + 1) / 2) * canvas.clientWidth, y: ((1 - ny) / 2) * canvas.clientHeight, z };
  }
  // The view frames the box of every position the body has taken (the rest shape at first), so
  // that a body that falls or swings away from where it started stays in view; it stops
  // following as soon as the person moves the camera or grabs the body.
  let framed = null;   // { lo, hi }, or null once the person took the camera over
  function frameBox(box) {
    camera.target = scale(add(box.lo, box.hi), 0.5);
    camera.radius = norm(sub(box.hi, box.lo)) / 2 || 1;
    // The narrower of the two half-angles: on a portrait page the sides bound the view.
    const half = Math.atan(Math.tan(camera.fov / 2) * Math.min(1, aspect()));
    camera.distance = (camera.radius / Math.sin(half)) * 1.05;
  }
  // The box { lo, hi } grown by the finite coordinates of `coords` (x, y, z per vertex): a
  // diverged method's frame moves nothing.
  function grownBox(box, coords) {
    const lo = [...box.lo], hi = [...box.hi];
    for (let i = 0; i < coords.length; i += 3) {
      for (let c = 0; c < 3; c++) {
        const x = coords[i + c];
        if (!Number.isFinite(x)) continue;
        if (x < lo[c]) lo[c] = x;
        if (x > hi[c]) hi[c] = x;
      }
    }
    return { lo, hi };
  }
  function fitCamera() {
    const empty = { lo: [Infinity, Infinity, Infinity], hi: [-Infinity, -Infinity, -Infinity] };
    framed = grownBox(empty, mesh.rest);
    frameBox(framed);
  }
  // Grows the framed box by the latest positions; the camera moves only when the box grew by
  // more than 1 % of its size, so a body at rest or swinging inside it leaves the view alone.
  function followBody() {
    if (!framed) return;
    const { lo, hi } = grownBox(framed, positions);
    const size = norm(sub(framed.hi, framed.lo));
    if (norm(sub(lo, framed.lo)) + norm(sub(hi, framed.hi)) > 0.01 * size) {
      framed = { lo, hi };
      frameBox(framed);
    }
  }
  const takeCamera = () => { framed = null; };
  const vertex = (i) => [positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]];

  // Nearest hit of a ray on the surface (Möller–Trumbore), or null.
  function pick(x, y) {
    if (!mesh || !positions) return null;
    const { origin, dir } = ray(x, y);
    let best = null;
    const tri = mesh.triangles;
    for (let k = 0; k < tri.length; k += 3) {
      const a = vertex(tri[k]), b = vertex(tri[k + 1]), c = vertex(tri[k + 2]);
      const e1 = sub(b, a), e2 = sub(c, a);
      const p = cross(dir, e2);
      const det = dot(e1, p);
      if (Math.abs(det) < 1e-14) continue;
      const inv = 1 / det;
      const s = sub(origin, a);
      const u = dot(s, p) * inv;
      if (u < 0 || u > 1) continue;
      const q = cross(s, e1);
      const v = dot(dir, q) * inv;
      if (v < 0 || u + v > 1) continue;
      const t = dot(e2, q) * inv;
      if (t > 0 && (!best || t < best.t)) {
        const w = [1 - u - v, u, v];
        const corner = w.indexOf(Math.max(...w));
        best = { t, point: add(origin, scale(dir, t)), vertex: tri[k + corner] };
      }
    }
    return best;
  }

  // ---- GL ----
  function shader(type, source) {
    const s = gl.createShader(type);
    gl.shaderSource(s, source);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  }
  function program(vs, fs) {
    const p = gl.createProgram();
    gl.attachShader(p, shader(gl.VERTEX_SHADER, vs));
    gl.attachShader(p, shader(gl.FRAGMENT_SHADER, fs));
    gl.bindAttribLocation(p, 0, 'position');
    gl.bindAttribLocation(p, 1, 'normal');
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    return p;
  }
  let surfaceProgram, markerProgram, buffers;
  function setupGl() {
    surfaceProgram = program(`#version 300 es
      in vec3 position; in vec3 normal;
      uniform mat4 viewProjection;
      out vec3 vNormal; out vec3 vPosition;
      void main() { vNormal = normal; vPosition = position; gl_Position = viewProjection * vec4(position, 1.0); }`,
    `#version 300 es
      precision highp float;
      in vec3 vNormal; in vec3 vPosition;
      uniform vec3 eye; uniform vec3 lightBias;
      out vec4 color;
      void main() {
        vec3 n = normalize(vNormal);
        vec3 v = normalize(eye - vPosition);
        if (dot(n, v) < 0.0) n = -n;
        vec3 l = normalize(v + lightBias);
        float diffuse = max(dot(n, l), 0.0);
        float specular = pow(max(dot(n, normalize(l + v)), 0.0), 48.0);
        vec3 base = vec3(0.36, 0.62, 0.86);
        color = vec4(base * (0.22 + 0.78 * diffuse) + vec3(0.28) * specular, 1.0);
      }`);
    markerProgram = program(`#version 300 es
      in vec3 position;
      uniform mat4 viewProjection; uniform float size;
      void main() { gl_Position = viewProjection * vec4(position, 1.0); gl_PointSize = size; }`,
    `#version 300 es
      precision mediump float;
      uniform vec3 tint; out vec4 color;
      void main() { color = vec4(tint, 1.0); }`);
    buffers = {
      position: gl.createBuffer(), normal: gl.createBuffer(), index: gl.createBuffer(),
      pinned: gl.createBuffer(), marker: gl.createBuffer(),
    };
    gl.enable(gl.DEPTH_TEST);
    gl.clearColor(0.125, 0.14, 0.17, 1);
  }
  function uploadMesh() {
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.index);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, mesh.triangles, gl.STATIC_DRAW);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.pinned);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, mesh.pinned, gl.STATIC_DRAW);
  }
  function computeNormals() {
    normals.fill(0);
    const t = mesh.triangles, p = positions;
    for (let k = 0; k < t.length; k += 3) {
      const a = 3 * t[k], b = 3 * t[k + 1], c = 3 * t[k + 2];
      const e1x = p[b] - p[a], e1y = p[b + 1] - p[a + 1], e1z = p[b + 2] - p[a + 2];
      const e2x = p[c] - p[a], e2y = p[c + 1] - p[a + 1], e2z = p[c + 2] - p[a + 2];
      const nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
      for (const i of [a, b, c]) { normals[i] += nx; normals[i + 1] += ny; normals[i + 2] += nz; }
    }
  }
  function draw() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, w, h);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (!mesh || !positions) return;
    if (meshDirty) {
      computeNormals();
      gl.bindBuffer(gl.ARRAY_BUFFER, buffers.position);
      gl.bufferData(gl.ARRAY_BUFFER, positions, gl.DYNAMIC_DRAW);
      gl.bindBuffer(gl.ARRAY_BUFFER, buffers.normal);
      gl.bufferData(gl.ARRAY_BUFFER, normals, gl.DYNAMIC_DRAW);
      meshDirty = false;
    }
    const vp = viewProjection();
    gl.useProgram(surfaceProgram);
    gl.uniformMatrix4fv(gl.getUniformLocation(surfaceProgram, 'viewProjection'), false, vp);
    gl.uniform3fv(gl.getUniformLocation(surfaceProgram, 'eye'), basis().eye);
    // A light from above the viewer, above as the scene has it.
    gl.uniform3fv(gl.getUniformLocation(surfaceProgram, 'lightBias'), inWorld(0.35, 0.8, 0.25));
    gl.bindBuffer(gl.ARRAY_BUFFER, buffers.position);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffers.normal);
    gl.enableVertexAttribArray(1);
    gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.index);
    gl.drawElements(gl.TRIANGLES, mesh.triangles.length, gl.UNSIGNED_INT, 0);
    gl.disableVertexAttribArray(1);
    // Markers: pinned vertices, then the drag's grab point and target.
    gl.useProgram(markerProgram);
    gl.uniformMatrix4fv(gl.getUniformLocation(markerProgram, 'viewProjection'), false, vp);
    // A few pins (a body held at a point or along a line) are drawn larger and in front of the
    // surface, so that where it hangs from shows from every side.
    const fewPins = mesh.pinned.length < 8;
    gl.uniform1f(gl.getUniformLocation(markerProgram, 'size'), (fewPins ? 10 : 5) * dpr);
    gl.uniform3fv(gl.getUniformLocation(markerProgram, 'tint'), [0.9, 0.2, 0.2]);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffers.position);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.pinned);
    if (fewPins) gl.disable(gl.DEPTH_TEST);
    if (mesh.pinned.length) gl.drawElements(gl.POINTS, mesh.pinned.length, gl.UNSIGNED_INT, 0);
    if (fewPins) gl.enable(gl.DEPTH_TEST);
    if (drag && drag.target) {
      const line = new Float32Array([...vertex(drag.vertex), ...drag.target]);
      gl.bindBuffer(gl.ARRAY_BUFFER, buffers.marker);
      gl.bufferData(gl.ARRAY_BUFFER, line, gl.DYNAMIC_DRAW);
      gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
      gl.disable(gl.DEPTH_TEST);
      gl.uniform3fv(gl.getUniformLocation(markerProgram, 'tint'), [1.0, 0.85, 0.2]);
      gl.drawArrays(gl.LINES, 0, 2);
      gl.uniform1f(gl.getUniformLocation(markerProgram, 'size'), 9 * dpr);
      gl.drawArrays(gl.POINTS, 1, 1);
      gl.enable(gl.DEPTH_TEST);
    }
  }

  // ---- connection ----
  const socket = new WebSocket(`ws://${location.host}/ws`);
  socket.binaryType = 'arraybuffer';
  const send = (message) => { if (socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message)); };
  let messageTimer = null;
  // The server's texts quote keys and commands between backticks, as the terminal's do: shown
  // as code, each piece set as text (never as markup). Rebuilt only when the text changes.
  function setQuoted(element, text) {
    if (element.dataset.text === text) return;
    element.dataset.text = text;
    const pieces = text.split('`');
    // A backtick without its pair (a client's own text echoed in an error) stays a backtick.
    if (pieces.length % 2 === 0) pieces.push(`\`${pieces.pop()}`);
    element.replaceChildren(...pieces.map((piece, i) => {
      if (i % 2 === 0 || i === pieces.length - 1) return document.createTextNode(piece);
      const code = document.createElement('code');
      code.textContent = piece;
      return code;
    }));
  }
  function showMessage(text) {
    setQuoted($('message'), text);
    clearTimeout(messageTimer);
    messageTimer = setTimeout(() => setQuoted($('message'), ''), 5000);
  }
  socket.onclose = () => {
    setQuoted($('status'), 'disconnected from the server (reload when it runs again)');
    $('status').className = 'failed';
    // Nothing steps any more: no figures of a simulation that is gone, no controls that would
    // do nothing.
    for (const id of ['sps', 'cost', 'its', 'rtf', 'step', 'fps', 'beyond']) $(id).textContent = '–';
    for (const control of document.querySelectorAll('#hud button, #hud input, #hud select')) {
      control.disabled = true;
    }
    $('hud').classList.add('disconnected');
  };
  socket.onmessage = (event) => {
    if (typeof event.data === 'string') { onEvent(JSON.parse(event.data)); return; }
    const data = new DataView(event.data);
    const kind = data.getUint32(0, true);
    if (kind === 1) {
      const n = data.getUint32(4, true), m = data.getUint32(8, true), p = data.getUint32(12, true);
      const rest = new Float32Array(event.data.slice(16, 16 + 12 * n));
      const triangles = new Uint32Array(event.data.slice(16 + 12 * n, 16 + 12 * n + 12 * m));
      const pinned = new Uint32Array(event.data.slice(16 + 12 * n + 12 * m, 16 + 12 * n + 12 * m + 4 * p));
      mesh = { n, rest, triangles, pinned };
      positions = new Float32Array(rest);
      normals = new Float32Array(3 * n);
      meshDirty = true;
      fitCamera();
      uploadMesh();
    } else if (kind === 2 && mesh) {
      const n = data.getUint32(4, true);
      if (n !== mesh.n) return;
      frameStep = data.getFloat64(8, true);
      positions.set(new Float32Array(event.data, 24, 3 * n));
      followBody();
      meshDirty = true;
      framesShown += 1;
      frameTimes.push(performance.now());
    }
  };
  function onEvent(e) {
    switch (e.type) {
      case 'hello': {
        hello = e;
        setUp(Array.isArray(e.up) && e.up.length === 3 ? e.up : [0, 1, 0]);
        $('scene').textContent = `${e.scene} · h = ${e.time_step * 1000} ms`;
        const select = $('method');
        select.replaceChildren(...e.methods.map((name) => new Option(name, name)));
        select.value = e.method;
        $('radius').value = +e.radius.toPrecision(3);
        $('stiffness').value = +e.stiffness.toPrecision(3);
        break;
      }
      case 'state': onState(e); break;
      case 'grabbed':
        if (drag && drag.pending) {
          drag.pending = false;
          drag.handle = e.handle;
          if (drag.released) { send({ type: 'release', handle: e.handle }); drag = null; }
          else drag.sent = null;
        } else {
          send({ type: 'release', handle: e.handle });
        }
        break;
      case 'released':
        if (drag && drag.handle === e.handle) drag = null;
        if (e.reason !== 'released') showMessage(`handle released: ${e.reason}`);
        break;
      case 'error':
        if (e.request === 'grab' && drag && drag.pending) drag = null;
        showMessage(e.message);
        break;
      default: break;
    }
  }
  function fixed(x, digits) { return Number.isFinite(x) ? x.toFixed(digits) : '–'; }
  function onState(s) {
    state = s;
    $('method').value = s.method;
    $('sps').textContent = fixed(s.steps_per_second, 0);
    // What a step costs: in real time steps/s stays at 1/h whatever that is, so this is what
    // tells the methods apart.
    $('cost').textContent = !(Number.isFinite(s.step_ms) && s.step_ms > 0) ? '–'
      : s.step_ms >= 100 ? s.step_ms.toFixed(0) : s.step_ms.toPrecision(3);
    $('its').textContent = fixed(s.iterations_per_step, 1);
    $('rtf').textContent = `${fixed(s.real_time_factor, 2)}×`;
    $('step').textContent = `${s.step}, ${fixed(s.time, 2)} s`;
    // Full space has no training poses (null): a dash.
    const beyond = s.beyond_training;
    $('beyond').textContent = Number.isFinite(beyond) ? `${(100 * beyond).toFixed(0)} %` : '–';
    setQuoted($('status'), s.status);
    $('status').className = s.failure ? 'failed' : s.paused ? 'paused'
      : !s.real_time ? 'behind' : s.extrapolating ? 'extrapolating' : '';
    $('pause').textContent = s.paused ? 'run' : 'pause';
    $('single').disabled = !s.paused;
    $('gravity').checked = s.gravity;
  }

  // ---- controls ----
  $('method').onchange = () => send({ type: 'method', name: $('method').value });
  $('pause').onclick = () => send({ type: 'pause', paused: !(state && state.paused) });
  $('single').onclick = () => send({ type: 'step' });
  $('reset').onclick = () => {
    send({ type: 'reset' });
    // Still following: frame the rest shape again (a method that flew off widened the box).
    if (framed && mesh) fitCamera();
  };
  $('gravity').onchange = () => send({ type: 'gravity', enabled: $('gravity').checked });

  // ---- pointer: drag the body, or orbit, pan and zoom ----
  let drag = null;   // { pending, handle, vertex, planePoint, normal, target, sent, released }
  let orbit = null;  // { x, y, pan }
  function grabSettings() {
    const r = parseFloat($('radius').value), k = parseFloat($('stiffness').value);
    const out = {};
    if (Number.isFinite(r) && r > 0) out.radius = r;
    if (Number.isFinite(k) && k > 0) out.stiffness = k;
    // A field left empty takes the session's default; one that holds anything else but a
    // positive number (a browser gives '' for text that is not a number) is said.
    const ignored = [['grab radius', 'radius'], ['stiffness', 'stiffness']]
      .filter(([, key]) => !(key in out) && ($(key).value.trim() !== '' || $(key).validity.badInput))
      .map(([name]) => name);
    if (ignored.length === 1) {
      showMessage(`the ${ignored[0]} must be a positive number; the session's default is used`);
    } else if (ignored.length === 2) {
      showMessage("the grab radius and stiffness must be positive numbers; the session's defaults are used");
    }
    return out;
  }
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  // Pointer events: a mouse, a pen or one finger grabs the body or orbits; two fingers pinch
  // to zoom (and stop what one finger was doing).
  const touches = new Map();  // pointerId → { x, y } of each finger down
  let pinch = null;           // { distance } between the two fingers
  function fingerDistance() {
    const [a, b] = [...touches.values()];
    return Math.hypot(a.x - b.x, a.y - b.y);
  }
  function letGo() {
    if (drag) {
      if (drag.handle !== null) { send({ type: 'release', handle: drag.handle }); drag = null; }
      else drag.released = true;
    }
    orbit = null;
  }
  canvas.addEventListener('pointerdown', (e) => {
    takeCamera();
    if (e.pointerType === 'touch') {
      touches.set(e.pointerId, { x: e.clientX, y: e.clientY });
      if (touches.size >= 2) {
        letGo();
        if (touches.size === 2) pinch = { distance: fingerDistance() };
        return;
      }
    }
    canvas.setPointerCapture(e.pointerId);
    if (e.button === 0 && !e.shiftKey) {
      const hit = pick(e.offsetX, e.offsetY);
      if (hit) {
        drag = { pending: true, handle: null, vertex: hit.vertex, planePoint: hit.point,
          normal: basis().forward, target: hit.point, sent: hit.point, released: false };
        send({ type: 'grab', point: hit.point, ...grabSettings() });
        return;
      }
    }
    orbit = { x: e.clientX, y: e.clientY, pan: e.button !== 0 || e.shiftKey };
  });
  canvas.addEventListener('pointermove', (e) => {
    if (touches.has(e.pointerId)) {
      touches.set(e.pointerId, { x: e.clientX, y: e.clientY });
      if (pinch) {
        const d = fingerDistance();
        if (d > 0 && pinch.distance > 0) camera.distance *= pinch.distance / d;
        pinch.distance = d;
        return;
      }
    }
    if (drag) {
      const rect = canvas.getBoundingClientRect();
      const { origin, dir } = ray(e.clientX - rect.left, e.clientY - rect.top);
      const denom = dot(dir, drag.normal);
      if (Math.abs(denom) > 1e-9) {
        const t = dot(sub(drag.planePoint, origin), drag.normal) / denom;
        if (t > 0) drag.target = add(origin, scale(dir, t));
      }
    } else if (orbit) {
      const dx = e.clientX - orbit.x, dy = e.clientY - orbit.y;
      orbit.x = e.clientX; orbit.y = e.clientY;
      if (orbit.pan) {
        const { right, up } = basis();
        const s = (2 * camera.distance * Math.tan(camera.fov / 2)) / canvas.clientHeight;
        camera.target = add(camera.target, add(scale(right, -dx * s), scale(up, dy * s)));
      } else {
        camera.yaw -= dx * 0.008;
        camera.pitch = Math.max(-1.5, Math.min(1.5, camera.pitch + dy * 0.008));
      }
    }
  });
  function pointerEnd(e) {
    const finger = touches.delete(e.pointerId);
    if (finger && pinch) {
      // The pinch ends when a finger lifts; the other does nothing until it lifts too.
      if (touches.size < 2) pinch = null;
      return;
    }
    if (finger && touches.size > 0) return;
    letGo();
  }
  canvas.addEventListener('pointerup', pointerEnd);
  canvas.addEventListener('pointercancel', pointerEnd);
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    takeCamera();
    camera.distance *= Math.exp(e.deltaY * 0.001);
  }, { passive: false });

  // ---- the loop: send the drag's latest target once per display frame, draw ----
  function tick() {
    if (drag && drag.handle !== null && drag.target !== drag.sent) {
      send({ type: 'move', handle: drag.handle, target: drag.target });
      drag.sent = drag.target;
    }
    const now = performance.now();
    while (frameTimes.length && now - frameTimes[0] > 1000) frameTimes.shift();
    // Frames received over the last second, while the server is there to send them.
    if (socket.readyState !== WebSocket.CLOSED) $('fps').textContent = frameTimes.length;
    draw();
    requestAnimationFrame(tick);
  }
  if (!gl) {
    setQuoted($('status'), 'this browser has no WebGL2');
    $('status').className = 'failed';
  } else {
    setupGl();
    requestAnimationFrame(tick);
  }

  // ---- for tests and scripts (Runtime.evaluate): where things are ----
  window.viewerDebug = {
    ready: () => Boolean(mesh && positions && state && framesShown > 0 && gl),
    framesShown: () => framesShown,
    frameStep: () => frameStep,
    state: () => state,
    hud: () => $('hud').innerText,
    // Shows `text` as a message from the server is shown.
    say: (text) => showMessage(text),
    position: (i) => vertex(i),
    screenOf: (i) => project(vertex(i)),
    handle: () => (drag ? drag.handle : null),
    target: () => (drag ? drag.target : null),
    cameraDistance: () => camera.distance,
    following: () => framed !== null,
    vertexCount: () => (mesh ? mesh.n : 0),
    pinned: () => (mesh ? Array.from(mesh.pinned) : []),
    // How many vertices are drawn outside the canvas.
    outsideView: () => {
      let n = 0;
      for (let i = 0; mesh && i < mesh.n; i++) {
        const s = project(vertex(i));
        if (!(s.z > 0 && s.x >= 0 && s.x <= canvas.clientWidth && s.y >= 0 && s.y <= canvas.clientHeight)) n += 1;
      }
      return n;
    },
    // A surface vertex far from the pins that the mouse can pick where it is drawn, inside the
    // silhouette (the body around it for 10 pixels), so that a little motion does not matter.
    grabCandidate: () => {
      if (!mesh) return null;
      const pinnedSet = new Set(mesh.pinned);
      let centre = [0, 0, 0];
      const anchor = mesh.pinned.length ? Array.from(mesh.pinned) : [...Array(mesh.n).keys()];
      for (const i of anchor) centre = add(centre, vertex(i));
      centre = scale(centre, 1 / anchor.length);
      const order = [...Array(mesh.n).keys()].filter((i) => !pinnedSet.has(i))
        .sort((a, b) => norm(sub(vertex(b), centre)) - norm(sub(vertex(a), centre)));
      for (const i of order.slice(0, 200)) {
        const s = project(vertex(i));
        if (s.x < 320 || s.y < 20 || s.x > canvas.clientWidth - 20 || s.y > canvas.clientHeight - 20) continue;
        const hit = pick(s.x, s.y);
        if (!hit || norm(sub(hit.point, vertex(i))) > 1e-3 * camera.radius) continue;
        const around = [[10, 0], [-10, 0], [0, 10], [0, -10]].every(([dx, dy]) => pick(s.x + dx, s.y + dy));
        if (around) return { vertex: i, x: s.x, y: s.y };
      }
      return null;
    },
  };
})();
