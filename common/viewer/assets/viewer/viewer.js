// The cdm viewer: a team of quadcopters in 3-D (three.js), its four safety margins, the live
// curves of Figs. 8 and 11, and either a replay timeline or a live Server-Sent Events stream.
// DOM contract for tests: #cdm-status carries data-agents, data-tick, data-verdict and data-lost
// (members lost by the shown tick: hidden, and the graph drawn is the repaired one), and
// data-airspace (the fence's sides drawn, then the obstacles drawn, by name), and
// data-commands-accepted / data-commands-refused (commands switched by the shown tick).
import * as THREE from 'three';
import { OrbitControls } from 'orbit';

const ROLE_COLOUR = { primary: 0xff5a4e, secondary: 0xffb13b, follower: 0x4ea3ff };
const $ = (id) => document.getElementById(id);

const embedded = JSON.parse($('cdm-scene').textContent);
const live = embedded === null;
const scene = live ? await (await fetch('scene.json')).json() : embedded;
const n = scene.agents.length;
const frames = scene.frames; // replay: all; live: grows (positions kept for the newest only)
let shown = -1; // index into frames
let verdict = scene.verdict;

// --- 3-D scene -------------------------------------------------------------------------------
const view = $('view');
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.setSize(view.clientWidth, view.clientHeight);
view.appendChild(renderer.domElement);
const world = new THREE.Scene();
world.background = new THREE.Color(0x10141c);
const camera = new THREE.PerspectiveCamera(45, view.clientWidth / view.clientHeight, 0.1, 1e6);
camera.up.set(0, 0, 1);
const controls = new OrbitControls(camera, renderer.domElement);
world.add(new THREE.AmbientLight(0xffffff, 0.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(1, -1, 2);
world.add(sun);

const sphere = new THREE.SphereGeometry(1, 16, 12);
const agents = new THREE.InstancedMesh(sphere, new THREE.MeshLambertMaterial(), n);
scene.agents.forEach((a, k) => agents.setColorAt(k, new THREE.Color(ROLE_COLOUR[a.role] ?? 0xffffff)));
world.add(agents);

function lines(count, colour, opacity, loop) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(count * 3), 3));
  const m = new THREE.LineBasicMaterial({ color: colour, transparent: opacity < 1, opacity });
  const obj = loop ? new THREE.LineLoop(g, m) : new THREE.LineSegments(g, m);
  obj.frustumCulled = false;
  world.add(obj);
  return obj;
}
const poly = scene.polygon.length;
const polygon = lines(poly, 0x7cf29a, 1, true);
const prism = lines(poly * 6, 0x7cf29a, 0.45, false); // two bases and the side edges
// The graph in force at a tick: the t0 graph, then each loss's repair (`scene.graphs`).
const graphs = [{ tick: 0, edges: scene.edges }].concat(scene.graphs ?? []);
const edges_at = (tick) => graphs.filter((g) => g.tick <= tick).pop().edges;
const graph = lines(Math.max(...graphs.map((g) => g.edges.length)) * 2, 0x9aa7b8, 0.35, false);
// `?graph=1` opens the page with the communication graph shown.
graph.visible = new URLSearchParams(location.search).get('graph') === '1';
$('graph').checked = graph.visible;
$('graph').addEventListener('change', (e) => { graph.visible = e.target.checked; draw(); });
const track = new THREE.Line(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0xffffff }));
track.frustumCulled = false;
world.add(track);

// --- airspace: the geofence as a wire prism, obstacles as translucent solids --------
const FENCE_COLOUR = 0x5fd3f3, OBSTACLE_COLOUR = 0xc77dff;
const drawn = { fence: 0, obstacles: [] }; // data-airspace, for tests: what was added
function wire(points, colour) {
  const g = new THREE.BufferGeometry().setFromPoints(points);
  const obj = new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: colour }));
  world.add(obj);
  return obj;
}
if (scene.geofence) {
  const f = scene.geofence, m = f.polygon.length, pts = [];
  const at = (k, z) => new THREE.Vector3(f.polygon[k % m][0], f.polygon[k % m][1], z);
  for (let k = 0; k < m; k++) {
    pts.push(at(k, f.min_z_m), at(k + 1, f.min_z_m), at(k, f.max_z_m), at(k + 1, f.max_z_m));
    pts.push(at(k, f.min_z_m), at(k, f.max_z_m));
  }
  drawn.fence = wire(pts, FENCE_COLOUR).geometry.attributes.position.count / 6;
}
for (const o of scene.obstacles ?? []) {
  // A box has `min` and `max`; a vertical cylinder `center`, `radius_m`, `min_z_m`, `max_z_m`.
  const box = o.min !== undefined;
  const lo = box ? o.min : [o.center[0], o.center[1], o.min_z_m];
  const hi = box ? o.max : [o.center[0], o.center[1], o.max_z_m];
  const height = hi[2] - lo[2];
  const geometry = box
    ? new THREE.BoxGeometry(hi[0] - lo[0], hi[1] - lo[1], height)
    : new THREE.CylinderGeometry(o.radius_m, o.radius_m, height, 32).rotateX(Math.PI / 2);
  const solid = new THREE.Mesh(geometry, new THREE.MeshLambertMaterial({
    color: OBSTACLE_COLOUR, transparent: true, opacity: 0.35, depthWrite: false,
  }));
  solid.position.set((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
  solid.name = o.name;
  world.add(solid);
  // 20 degrees: a box's twelve edges, a cylinder's two rims (not its 32 side seams).
  const edges = new THREE.LineSegments(new THREE.EdgesGeometry(geometry, 20),
    new THREE.LineBasicMaterial({ color: OBSTACLE_COLOUR }));
  edges.position.copy(solid.position);
  world.add(edges);
  drawn.obstacles.push(o.name);
}

const pos = (f, k) => new THREE.Vector3(f.p[3 * k] / 1000, f.p[3 * k + 1] / 1000, f.p[3 * k + 2] / 1000);

function frame_to_scene(f) {
  const m = new THREE.Matrix4();
  const lost = new Set(f.lost ?? []);
  for (let k = 0; k < n; k++) {
    const r = pos(f, k);
    const size = lost.has(k) ? 0 : radius; // a lost member leaves the scene
    m.makeScale(size, size, size).setPosition(r);
    agents.setMatrixAt(k, m);
  }
  agents.instanceMatrix.needsUpdate = true;
  agents.computeBoundingSphere();
  const verts = scene.polygon.map((k) => pos(f, k));
  const pa = polygon.geometry.attributes.position;
  verts.forEach((v, i) => pa.setXYZ(i, v.x, v.y, v.z));
  pa.needsUpdate = true;
  if (poly >= 3) {
    // Theorem 3's prism: the polygon shifted by +-(delta + eps) along its normal.
    const normal = new THREE.Vector3().subVectors(verts[1], verts[0])
      .cross(new THREE.Vector3().subVectors(verts[2], verts[0])).normalize()
      .multiplyScalar(scene.half_height_m);
    const up = verts.map((v) => v.clone().add(normal));
    const down = verts.map((v) => v.clone().sub(normal));
    const a = prism.geometry.attributes.position;
    let i = 0;
    const seg = (p, q) => { a.setXYZ(i++, p.x, p.y, p.z); a.setXYZ(i++, q.x, q.y, q.z); };
    for (let k = 0; k < poly; k++) {
      const j = (k + 1) % poly;
      seg(up[k], up[j]);
      seg(down[k], down[j]);
      seg(up[k], down[k]);
    }
    a.needsUpdate = true;
  }
  if (graph.visible) {
    const a = graph.geometry.attributes.position;
    const edges = edges_at(f.tick);
    edges.forEach(([from, to], i) => {
      const p = pos(f, from), q = pos(f, to);
      a.setXYZ(2 * i, p.x, p.y, p.z);
      a.setXYZ(2 * i + 1, q.x, q.y, q.z);
    });
    graph.geometry.setDrawRange(0, 2 * edges.length);
    a.needsUpdate = true;
  }
}

// Agent size and camera from the extent of the given frames (replay: the whole flight).
let radius = 0.3;
function frame_camera(fs) {
  const box = new THREE.Box3();
  const step = Math.max(1, Math.floor(fs.length / 50));
  for (let i = 0; i < fs.length; i += step) for (let k = 0; k < n; k++) box.expandByPoint(pos(fs[i], k));
  for (let k = 0; k < n; k++) box.expandByPoint(pos(fs[fs.length - 1], k));
  const size = box.getSize(new THREE.Vector3()).length() || 10;
  radius = Math.max(scene.eps_m, size / 150);
  const centre = box.getCenter(new THREE.Vector3());
  controls.target.copy(centre);
  camera.position.copy(centre).add(new THREE.Vector3(0.25, -0.8, 0.6).multiplyScalar(size * 1.3));
  camera.near = size / 1000;
  camera.far = size * 100;
  camera.updateProjectionMatrix();
  controls.update();
}

// --- margins, curves, status -----------------------------------------------------------------
function level(ratio) { return ratio < 0.7 ? '#43d17a' : ratio < 1 ? '#ffb13b' : '#ff4d4d'; }
function margins(f) {
  // Each row: value, limit, and how close to the limit (1 = at it).
  const rows = [
    ['separation', f.sep, 2 * scene.eps_m, f.sep < 0 ? 0 : (2 * scene.eps_m) / Math.max(f.sep, 1e-9), 'm, >= 2 eps'],
    ['tracking', f.dev, scene.delta_m, f.dev / scene.delta_m, 'm, <= delta'],
    ['boundary', f.bnd, 0, f.bnd < 0 ? 0 : 1 / (1 + f.bnd), 'm, >= 0'],
    ['lambda_1', f.l1, scene.lambda_cd_min, scene.lambda_cd_min / Math.max(f.l1, 1e-9), '>= lambda_CD,min'],
  ];
  $('margins').innerHTML = rows.map(([name, v, lim, ratio, unit]) =>
    `<div class="m"><div class="bar" style="background:${level(ratio)}"></div><span>${name}</span>` +
    `<b>${v.toFixed(3)} (${lim.toFixed(3)} ${unit})</b></div>`).join('');
}

const curves = $('curves');
function draw_curves() {
  const c = curves.getContext('2d');
  const w = curves.width, h = curves.height / 2;
  c.clearRect(0, 0, w, 2 * h);
  const t1 = Math.max(scene.last_tick * scene.dt_s, 1e-9);
  const upto = live ? frames.length : shown + 1;
  const plot = (y0, title, series) => {
    const vals = series.flatMap((s) => frames.slice(0, Math.max(upto, 1)).map(s.f)).concat(series.map((s) => s.limit ?? NaN)).filter(Number.isFinite);
    const lo = Math.min(...vals, 0), hi = Math.max(...vals, 1e-9);
    const X = (t) => 30 + (w - 40) * t / t1, Y = (v) => y0 + h - 18 - (h - 34) * (v - lo) / (hi - lo || 1);
    c.fillStyle = '#dfe6ee'; c.font = '11px sans-serif'; c.fillText(title, 30, y0 + 12);
    c.strokeStyle = '#445'; c.strokeRect(30, y0 + 16, w - 40, h - 34);
    for (const s of series) {
      if (s.limit !== undefined) {
        c.strokeStyle = s.colour; c.setLineDash([4, 3]); c.beginPath();
        c.moveTo(X(0), Y(s.limit)); c.lineTo(X(t1), Y(s.limit)); c.stroke(); c.setLineDash([]);
      }
      c.strokeStyle = s.colour; c.beginPath();
      frames.slice(0, upto).forEach((f, i) => (i ? c.lineTo : c.moveTo).call(c, X(f.t), Y(s.f(f))));
      c.stroke();
    }
  };
  plot(0, 'Fig. 8: lambda_1(U_D), dashed lambda_CD,min', [{ f: (f) => f.l1, colour: '#ffb13b', limit: scene.lambda_cd_min }]);
  plot(h, 'Fig. 11: D_B (blue, dashed 2 eps), D_S (green)', [
    { f: (f) => f.sep, colour: '#4ea3ff', limit: 2 * scene.eps_m },
    { f: (f) => f.bnd, colour: '#43d17a' }]);
}

let rate = null;
function status(f) {
  const s = $('cdm-status');
  s.dataset.agents = String(n);
  s.dataset.airspace = JSON.stringify(drawn);
  s.dataset.tick = String(f.tick);
  s.dataset.verdict = verdict;
  const lost = (f.lost ?? []).length;
  s.dataset.lost = String(lost);
  const switched = (scene.commands ?? []).filter((c) => c.tick <= f.tick);
  const accepted = switched.filter((c) => c.accepted).length;
  const refused = switched.length - accepted;
  s.dataset.commandsAccepted = String(accepted);
  s.dataset.commandsRefused = String(refused);
  const last = switched[switched.length - 1];
  const command_text = last === undefined ? '' :
    `\ncommands ${accepted} accepted, ${refused} refused; last: ${last.command} ` +
    (last.accepted ? 'accepted' : 'refused') + ` at tick ${last.tick}`;
  const rate_text = rate === null ? '' : `   ${Math.round(rate)} ticks/s`;
  s.textContent = `${scene.scenario}: ${n} agents, ${live ? 'live' : 'replay'}\n` +
    `tick ${f.tick} / ${scene.last_tick}   t = ${f.t.toFixed(2)} s${rate_text}\nverdict ${verdict}` +
    (lost > 0 ? `   lost ${lost}` : '') + command_text;
}

// --- selection: click an agent for its track and numbers --------------------------------------
let selected = null;
const ray = new THREE.Raycaster();
renderer.domElement.addEventListener('click', (e) => {
  const r = renderer.domElement.getBoundingClientRect();
  ray.setFromCamera(new THREE.Vector2(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1), camera);
  const hit = ray.intersectObject(agents)[0];
  selected = hit ? hit.instanceId : null;
  draw();
});
function show_selected(f) {
  const box = $('agent');
  if (selected === null) { box.style.display = 'none'; track.visible = false; return; }
  const a = scene.agents[selected], r = pos(f, selected);
  box.style.display = 'block';
  box.textContent = `agent ${a.id} (${a.role})\nx ${r.x.toFixed(3)}  y ${r.y.toFixed(3)}  z ${r.z.toFixed(3)} m`;
  const pts = frames.filter((g) => g.p && g.p.length).map((g) => pos(g, selected));
  track.geometry.setFromPoints(pts);
  track.visible = true;
}

// The camera follows the team's centroid (the user's orbit and zoom are kept).
function follow_team(f) {
  const c = new THREE.Vector3();
  for (let k = 0; k < n; k++) c.add(pos(f, k));
  c.divideScalar(Math.max(n, 1));
  const shift = c.sub(controls.target);
  controls.target.add(shift);
  camera.position.add(shift);
  controls.update();
}

function draw() {
  if (shown < 0) return;
  const f = frames[shown];
  if (f.p && f.p.length) { frame_to_scene(f); follow_team(f); }
  margins(f);
  status(f);
  draw_curves();
  show_selected(f);
  renderer.render(world, camera);
}

// --- replay ------------------------------------------------------------------------------------
const scrub = $('scrub');
let playing = !live;
function replay() {
  scrub.max = String(frames.length - 1);
  for (const v of scene.violations) {
    const i = frames.findIndex((f) => f.tick >= v.tick);
    const mark = document.createElement('div');
    mark.className = 'mark';
    mark.title = `${v.kind} at tick ${v.tick}: agents ${v.agents.join(', ')}`;
    mark.style.left = `${(100 * Math.max(i, 0)) / Math.max(frames.length - 1, 1)}%`;
    $('timeline').appendChild(mark);
  }
  // A mission's phases (take-off, segments, landing): a named line where each starts.
  for (const p of scene.phases || []) {
    const i = frames.findIndex((f) => f.t >= p.t_start_s);
    const mark = document.createElement('div');
    mark.className = 'phase';
    mark.textContent = p.name;
    mark.title = `${p.name}: t = ${p.t_start_s} to ${p.t_end_s} s`;
    mark.style.left = `${(100 * Math.max(i, 0)) / Math.max(frames.length - 1, 1)}%`;
    $('timeline').appendChild(mark);
  }
  // Commands: a line at each switch tick, green when accepted, red when refused (with why).
  for (const c of scene.commands || []) {
    const i = frames.findIndex((f) => f.tick >= c.tick);
    const mark = document.createElement('div');
    mark.className = c.accepted ? 'command' : 'command refused';
    mark.textContent = c.command;
    mark.title = `${c.command} ${c.accepted ? 'accepted' : 'refused'} at tick ${c.tick}` + (c.why ? `: ${c.why}` : '');
    mark.style.left = `${(100 * Math.max(i, 0)) / Math.max(frames.length - 1, 1)}%`;
    $('timeline').appendChild(mark);
  }
  scrub.addEventListener('input', () => { shown = Number(scrub.value); playing = false; $('play').textContent = 'play'; draw(); });
  $('play').addEventListener('click', () => {
    playing = !playing;
    if (playing && shown >= frames.length - 1) shown = 0;
    $('play').textContent = playing ? 'pause' : 'play';
  });
  // The page opens on the last tick (the run's outcome); play starts from the beginning.
  shown = frames.length - 1;
  scrub.value = String(shown);
  playing = false;
  $('play').textContent = 'play';
  let sim_t = frames[0].t, last = performance.now();
  const step = (now) => {
    const dt = (now - last) / 1000;
    last = now;
    if (playing) {
      sim_t = (shown >= 0 ? frames[shown].t : 0) + dt * Number($('speed').value);
      while (shown < frames.length - 1 && frames[shown + 1].t <= sim_t) shown++;
      if (shown >= frames.length - 1) { playing = false; $('play').textContent = 'play'; }
      scrub.value = String(shown);
      draw();
    }
    requestAnimationFrame(step);
  };
  requestAnimationFrame(step);
}

// --- live --------------------------------------------------------------------------------------
// `?frames=N` closes the stream after N frames with positions (data-first-tick records the first):
// a headless browser's --virtual-time-budget then sees an idle network and takes its snapshot.
function follow() {
  $('controls').style.display = 'none';
  const events = new EventSource('events');
  const limit = Number(new URLSearchParams(location.search).get('frames') || 0);
  let framed = false, full = 0;
  events.addEventListener('frame', (e) => {
    const msg = JSON.parse(e.data);
    if (msg.frame.rate !== undefined) rate = msg.frame.rate;
    if (msg.commands !== undefined) scene.commands = msg.commands;
    verdict = msg.verdict === 'SAFE' ? 'RUNNING' : msg.verdict;
    // Positions are kept for the newest frame only (the curves need the margins alone).
    if (shown >= 0 && frames[shown].p && frames[shown].p.length && msg.frame.p && msg.frame.p.length) frames[shown].p = [];
    frames.push(msg.frame);
    if (msg.frame.p && msg.frame.p.length) {
      shown = frames.length - 1;
      if (!framed) { frame_camera([msg.frame]); framed = true; $('cdm-status').dataset.firstTick = String(msg.frame.tick); }
      full += 1;
    }
    draw();
    if (limit > 0 && full >= limit) events.close();
  });
  events.addEventListener('end', (e) => {
    const msg = JSON.parse(e.data);
    verdict = msg.verdict;
    events.close();
    draw();
  });
}

window.addEventListener('resize', () => {
  renderer.setSize(view.clientWidth, view.clientHeight);
  camera.aspect = view.clientWidth / view.clientHeight;
  camera.updateProjectionMatrix();
  draw();
});
controls.addEventListener('change', () => renderer.render(world, camera));

if (live) {
  $('cdm-status').dataset.agents = String(n);
  follow();
} else {
  frame_camera([frames[frames.length - 1]]);
  replay();
  draw();
}
