#pragma once
// The HTML and script of a viewer page (view.cpp, octocd/view.hpp). Internal to validation/.
//
// The page reads its data from <script type="application/json" id="octocd-data"> (the
// numbers of the trace) and draws it with three.js (inlined before it). It records every
// error (window.onerror, console.error) in <pre id="octocd-errors"> and sets
// <body data-status="drawn"> once the first frame is rendered, so a headless browser
// (tests/cli/test_view_chromium.py) can tell a page that drew from one that failed.
#include <string>

namespace octocd::detail {

/// The whole page: `title` (plain text of numbers), `json` (already safe inside a script
/// element) and `js` (three.js and its examples, already safe inside a script element).
inline std::string view_page_html(const std::string& title, const std::string& json, const std::string& js) {
  static const char* const head = R"HTML(<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>)HTML";
  static const char* const style = R"HTML(</title>
<script>
window.octocdErrors = [];
window.addEventListener('error', function (e) { window.octocdErrors.push(String(e.message || e)); showErrors(); });
(function () { var ce = console.error; console.error = function () {
  window.octocdErrors.push(Array.prototype.join.call(arguments, ' ')); showErrors(); ce.apply(console, arguments); }; })();
function showErrors() { var p = document.getElementById('octocd-errors'); if (p) p.textContent = window.octocdErrors.join('\n'); }
</script>
<style>
html, body { margin: 0; height: 100%; overflow: hidden; font: 13px/1.35 sans-serif; background: #f4f4f2; }
#view { position: absolute; left: 400px; top: 0; right: 0; bottom: 0; }
#panel { position: absolute; left: 0; top: 0; bottom: 0; width: 400px; box-sizing: border-box; overflow: auto;
  background: #fff; border-right: 1px solid #bbb; padding: 8px; }
body.collapsed #view { left: 30px; } body.collapsed #panel { width: 30px; padding: 4px; overflow: hidden; }
body.collapsed #panel > :not(#toggle) { display: none; }
#toggle { float: right; font-size: 12px; }
#failure { font-weight: bold; color: #8a1010; margin: 4px 0; }
#panel h1 { font-size: 14px; margin: 0 0 4px 0; }
#figures { white-space: pre-wrap; font: 12px/1.3 monospace; margin: 6px 0; }
#note { color: #a04000; margin: 4px 0; }
#legend div { margin: 1px 0; } #legend span { display: inline-block; width: 12px; height: 12px; margin-right: 6px;
  vertical-align: middle; border: 1px solid #666; }
#octocd-errors { color: #b00; white-space: pre-wrap; margin: 0; }
input[type=range] { width: 100%; } select { max-width: 100%; }
</style></head>
<body data-status="loading">
<div id="view"></div>
<div id="panel">
<button id="toggle" title="hide or show this panel">&#9664;</button>
<h1 id="heading"></h1>
<div id="failure"></div>
<div id="about"></div>
<div id="note"></div>
<div><label>frame <b id="frame-label"></b><input id="slider" type="range"></label></div>
<div><label>contact <select id="pick"></select></label></div>
<div><label><input id="boxes" type="checkbox"> world AABBs of the other bodies</label></div>
<div><label><input id="impulses" type="checkbox"> the pair's impulses and friction cone</label></div>
<div id="figures"></div>
<div id="legend">
<div><span style="background:#e8642c"></span><span style="background:#56b4e9"></span>the item's bodies
 (pair: A orange, B sky blue)</div>
<div><span style="background:#c8c8c8"></span>other bodies (dark: static; without an item, a colour
 per body)</div>
<div><span style="background:none;border-color:#3a6fd8"></span>world AABBs (the item's: its colour; the
 others' with the box above)</div>
<div><span style="background:#1f3f9f"></span>engine normal at its point (length: depth x the pair's
 scale)</div>
<div><span style="background:#d01f1f"></span>engine normal of the selected contact</div>
<div><span style="background:#f08c00"></span>the row's point on B (/contacts/point_b), joined to its
 point: the impulse acts between the two</div>
<div><span style="background:#1a9a3a"></span>reference normal (SAT or FCL, the physics tier's own)</div>
<div><span style="background:#7b3fb0"></span>reference points (nearest points / contact point)</div>
<div><span style="background:#333"></span>normal impulse sum jn n; its ring: the cone mu jn</div>
<div><span style="background:#e0009b"></span>friction impulse sum jt3 from its tip (scalar jt: a
 ring of radius |jt|)</div>
<div id="scale"></div>
<div>drag: orbit, wheel: zoom, right drag: pan</div>
</div>
<pre id="octocd-errors"></pre>
</div>
<script>
)HTML";
  static const char* const between = R"HTML(
</script>
<script type="application/json" id="octocd-data">)HTML";
  static const char* const tail = R"HTML(</script>
<script>
(function () {
'use strict';
var D = JSON.parse(document.getElementById('octocd-data').textContent);
function $(id) { return document.getElementById(id); }
function v3(a) { return new THREE.Vector3(a[0], a[1], a[2]); }
function f4(x) { return x === null || x === undefined ? 'n/a' : Number(x).toPrecision(4); }
function fv(a) { return a ? '(' + a.map(function (x) { return Number(x).toFixed(3); }).join(', ') + ')' : 'n/a'; }
var item = D.item;
$('heading').textContent = document.title;
var about = 'trace ' + D.trace + ' (version ' + D.trace_version + (D.octocd_engine ? ', octocd engine' : '') +
  '): ' + D.bodies_in_trace + ' bodies, ' + D.frames_in_trace + ' frames. Drawn: ' + D.bodies.length +
  ' bodies (cap ' + D.cap + '), frames ' + D.frames[0].frame + '..' + D.frames[D.frames.length - 1].frame + '.';
if (D.failure) $('failure').textContent = 'Failing: ' + D.failure.row + '/' + D.failure.cause + ', figure ' +
  f4(D.failure.figure) + ' ' + D.failure.unit + ' (frame ' + D.frame + ')';
if (!D.has_contact_rows) about += ' This trace has no contact rows.';
if (D.contact_geometry === 'aabb') about += ' The engine resolves contacts on world AABBs: judged against box-box on them (AABB); the shapes\' reference is shown too.';
$('about').textContent = about;
$('note').textContent = D.note;

var view = $('view');
function viewSize() { return [view.clientWidth || window.innerWidth, view.clientHeight || window.innerHeight]; }
var renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
renderer.setSize(viewSize()[0], viewSize()[1]);
renderer.setClearColor(0xf4f4f2, 1);
view.appendChild(renderer.domElement);
var scene = new THREE.Scene();
var camera = new THREE.PerspectiveCamera(45, (view.clientWidth || 1) / (view.clientHeight || 1), 1e-4, 1e5);
scene.add(new THREE.AmbientLight(0xffffff, 0.55));
var sun = new THREE.DirectionalLight(0xffffff, 0.6); sun.position.set(1, 2, 1.5); scene.add(sun);
var controls = new THREE.OrbitControls(camera, renderer.domElement);
// Rendered on demand (three.js manual, "Rendering on demand"): a frame is drawn when the
// camera moves or the page's content changes, none while the page is idle.
var renderPending = false;
function render() { renderPending = false; renderer.render(scene, camera); }
function requestRender() { if (!renderPending) { renderPending = true; requestAnimationFrame(render); } }
controls.addEventListener('change', requestRender);

// Shapes (body frame).
var geoms = D.shapes.map(function (s) {
  var g;
  if (s.kind === 'box') {
    g = new THREE.BoxBufferGeometry(s.max[0] - s.min[0], s.max[1] - s.min[1], s.max[2] - s.min[2]);
    g.translate((s.max[0] + s.min[0]) / 2, (s.max[1] + s.min[1]) / 2, (s.max[2] + s.min[2]) / 2);
  } else if (s.kind === 'sphere') {
    g = new THREE.SphereBufferGeometry(s.radius, 24, 16); g.translate(s.center[0], s.center[1], s.center[2]);
  } else if (s.kind === 'hull') {
    var pts = []; for (var i = 0; i < s.vertices.length; i += 3) pts.push(new THREE.Vector3(s.vertices[i], s.vertices[i + 1], s.vertices[i + 2]));
    g = new THREE.ConvexBufferGeometry(pts);
  } else {
    g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(s.vertices, 3));
    g.setIndex(s.triangles);
    g.computeVertexNormals();
  }
  return g;
});
// Colours: the pair's A orange and B sky blue (told apart by colour-blind readers too), a
// body item orange, others neutral; without an item a colour per dynamic body.
var PALETTE = [0xe69f00, 0x56b4e9, 0x009e73, 0xd55e00, 0x0072b2, 0xcc79a7, 0xb8a800, 0x8c564b];
function bodyColor(b, k) {
  if (b.item) return item.kind === 'pair' && b.id === item.b ? 0x56b4e9 : 0xe8642c;
  if (b.static) return 0x6b6b6b;
  return item.kind === 'none' ? PALETTE[k % PALETTE.length] : 0xc8c8c8;
}
var bodies = D.bodies.map(function (b, k) {
  var color = bodyColor(b, k), strong = b.item || (item.kind === 'none' && !b.static);
  // A static item (a wall, the floor) stays see-through: the other body of its pair shows.
  var solid = strong && !b.static;
  var mat = new THREE.MeshLambertMaterial({ color: color, transparent: !solid, opacity: solid ? 0.85 : b.item ? 0.2 : 0.18,
    side: THREE.DoubleSide, depthWrite: solid });
  var mesh = new THREE.Mesh(geoms[b.shape], mat);
  mesh.add(new THREE.LineSegments(new THREE.EdgesGeometry(geoms[b.shape], 30),
    new THREE.LineBasicMaterial({ color: new THREE.Color(color).multiplyScalar(0.5) })));
  scene.add(mesh);
  var box = new THREE.Box3(new THREE.Vector3(), new THREE.Vector3());
  var helper = new THREE.Box3Helper(box, b.item ? color : 0x3a6fd8);
  helper.visible = b.item || item.kind === 'none';
  scene.add(helper);
  return { mesh: mesh, box: box, helper: helper };
});

// Camera on the item's dynamic bodies (its static ones when it has none; everything drawn
// without an item) at the first frame: a pair with a wall is seen at the body on the wall.
var first = D.frames.filter(function (f) { return f.frame === D.frame; })[0] || D.frames[0];
var focus = new THREE.Box3();
var itemDynamic = D.bodies.some(function (b) { return b.item && !b.static; });
D.bodies.forEach(function (b, k) {
  if (item.kind === 'none' || (b.item && (!b.static || !itemDynamic)))
    focus.union(new THREE.Box3(v3(first.aabbs[k][0]), v3(first.aabbs[k][1])));
});
var centre = new THREE.Vector3(), size = new THREE.Vector3();
focus.getCenter(centre); focus.getSize(size);
var radius = Math.max(size.length() / 2, 1e-3);
// Far enough for the arrows too (up to about 0.8 radius beyond a body).
camera.position.copy(centre).add(new THREE.Vector3(1.2, 0.9, 1.6).multiplyScalar(radius * 2.4));
controls.target.copy(centre); controls.update();
camera.near = radius / 1000; camera.far = radius * 1000; camera.updateProjectionMatrix();

// Arrows, per pair: the pair's deepest row or reference over the window draws as the
// stub plus 0.7 of the item's size; depth 0 as the stub. Impulses, per pair: the largest
// of its sum jn and friction over the window draws as 1.1 of the item's size (the cone's
// ring beyond the normals' arrowheads).
function key(p) { return p.a + ',' + p.b; }
var maxDepth = {}, maxImpulse = {};
function grow(m, k, v) { if (v > 0 && !(m[k] >= v)) m[k] = v; }
D.frames.forEach(function (f) {
  f.contacts.forEach(function (c) { grow(maxDepth, key(c), c.depth); });
  f.references.forEach(function (r) {
    if (r.judged.penetrating) grow(maxDepth, key(r), r.judged.depth);
    if (r.friction) { grow(maxImpulse, key(r), r.friction.jn_sum); grow(maxImpulse, key(r), r.friction.jt_sum); }
  });
});
var stub = radius * 0.12;
function depthScale(p) { var m = maxDepth[key(p)]; return m > 0 ? 0.7 * radius / m : 1; }
function impulseScale(p) { var m = maxImpulse[key(p)]; return m > 0 ? 1.1 * radius / m : 1; }
// Another pair's arrows at half the length: the item's stay the longest.
function arrowLength(depth, p) {
  var l = Math.max(depth, 0) * depthScale(p);
  return stub + (item.kind === 'none' || isItem(p) ? l : 0.5 * l);
}
var overlay = new THREE.Group(); scene.add(overlay);
function addArrow(dir, origin, length, color, width) {
  var d = v3(dir); if (d.lengthSq() === 0) return;
  d.normalize();
  var a = new THREE.ArrowHelper(d, origin, length, color, length * 0.25, length * 0.12 * width);
  onTop(a.line); onTop(a.cone); overlay.add(a);
}
// Overlays drawn over the shapes (never hidden inside a body).
function onTop(o) { o.material.depthTest = false; o.material.transparent = true; o.renderOrder = 10; }
function addLine(points, color, loop) {
  var g = new THREE.BufferGeometry().setFromPoints(points);
  var l = loop ? new THREE.LineLoop(g, new THREE.LineBasicMaterial({ color: color }))
               : new THREE.Line(g, new THREE.LineBasicMaterial({ color: color }));
  onTop(l); overlay.add(l);
}
// A ring of `r` around `centre` in the plane normal to unit `n`.
function ring(centre, n, r, color) {
  var u = new THREE.Vector3(1, 0, 0); if (Math.abs(n.x) > 0.9) u.set(0, 1, 0);
  u.sub(n.clone().multiplyScalar(u.dot(n))).normalize();
  var w = new THREE.Vector3().crossVectors(n, u), pts = [];
  for (var i = 0; i < 48; i++) {
    var t = 2 * Math.PI * i / 48;
    pts.push(centre.clone().add(u.clone().multiplyScalar(r * Math.cos(t))).add(w.clone().multiplyScalar(r * Math.sin(t))));
  }
  addLine(pts, color, true);
  return pts;
}
// The pair's friction: sum jn n from its rows' mean point, the cone mu jn as a ring at its
// tip (with four generators from the point), the friction impulse from the tip.
function drawFriction(f, r) {
  var fr = r.friction, s = impulseScale(r), n = v3(fr.jn), origin = new THREE.Vector3(), rows = 0;
  if (n.lengthSq() === 0 || !(fr.jn_sum > 0)) return;
  n.normalize();
  f.contacts.forEach(function (c) { if (c.a === r.a && c.b === r.b) { origin.add(rowPoint(f, c)); rows++; } });
  if (rows) origin.multiplyScalar(1 / rows);
  var tip = origin.clone().add(n.clone().multiplyScalar(fr.jn_sum * s));
  addArrow(fr.jn, origin, fr.jn_sum * s, 0x333333, 1.4);
  var rim = ring(tip, n, fr.cone * s, 0x333333);
  for (var i = 0; i < 48; i += 12) addLine([origin, rim[i]], 0x333333, false);
  if (fr.jt) addArrow(fr.jt, tip, fr.jt_sum * s, 0xe0009b, 2.2);
  else ring(tip, n, fr.jt_sum * s, 0xe0009b);
}
function addDot(p, color, r) {
  var m = new THREE.Mesh(new THREE.SphereBufferGeometry(r, 12, 8), new THREE.MeshBasicMaterial({ color: color }));
  onTop(m); m.position.copy(p); overlay.add(m);
}
function indexOf(id) { for (var k = 0; k < D.bodies.length; k++) if (D.bodies[k].id === id) return k; return -1; }
// Where a row without a point is drawn: the centre of the two world AABBs' overlap.
function rowPoint(f, c) {
  if (c.point) return v3(c.point);
  var A = f.aabbs[indexOf(c.a)], B = f.aabbs[indexOf(c.b)], p = new THREE.Vector3();
  for (var k = 0; k < 3; k++) p.setComponent(k, (Math.max(A[0][k], B[0][k]) + Math.min(A[1][k], B[1][k])) / 2);
  return p;
}

var slider = $('slider'), pick = $('pick');
slider.min = 0; slider.max = D.frames.length - 1; slider.step = 1;
slider.value = D.frames.indexOf(first);
function isItem(c) { return item.kind === 'pair' ? (c.a === item.a && c.b === item.b) :
  item.kind === 'body' ? (c.a === item.body || c.b === item.body) : false; }

function show(fi, keep) {
  var f = D.frames[fi];
  $('frame-label').textContent = f.frame + (f.state_frame !== undefined && f.state_frame !== f.frame ?
    ' (drawn at the recorded state of frame ' + f.state_frame + ')' : '') + (f.frame === D.frame ? (D.failure ? ' (the failing frame)' : ' (the frame asked for)') : '');
  D.bodies.forEach(function (b, k) {
    var o = bodies[k];
    o.mesh.position.copy(v3(f.x[k]));
    o.mesh.quaternion.set(f.q[k][1], f.q[k][2], f.q[k][3], f.q[k][0]);
    o.box.min.copy(v3(f.aabbs[k][0])); o.box.max.copy(v3(f.aabbs[k][1]));
  });
  if (!keep) {
    var previous = pick.value;
    while (pick.firstChild) pick.removeChild(pick.firstChild);
    var options = [];
    f.contacts.forEach(function (c, k) { options.push({ v: 'c' + k, t: 'pair (' + c.a + ', ' + c.b + ') row, depth ' + f4(c.depth), item: isItem(c) }); });
    f.references.forEach(function (r, k) { if (!r.in_contact) options.push({ v: 'r' + k, t: 'pair (' + r.a + ', ' + r.b + '): no contact row (reference only)', item: isItem(r) }); });
    options.sort(function (x, y) { return (y.item ? 1 : 0) - (x.item ? 1 : 0); });
    options.forEach(function (o) { var e = document.createElement('option'); e.value = o.v; e.textContent = o.t; pick.appendChild(e); });
    if (options.some(function (o) { return o.v === previous; }) && previous) pick.value = previous;
  }
  draw(f);
}

function draw(f) {
  while (overlay.children.length) overlay.remove(overlay.children[0]);
  var sel = pick.value || '', selected = null, selRef = null;
  if (sel[0] === 'c') { selected = f.contacts[+sel.slice(1)]; selRef = selected.ref === null ? null : f.references[selected.ref]; }
  if (sel[0] === 'r') selRef = f.references[+sel.slice(1)];
  var dot = radius * 0.02;
  f.references.forEach(function (r) {
    var showIt = r === selRef || isItem(r);
    if (!showIt) return;
    var j = r.judged, pa = v3(j.point_a), pb = v3(j.point_b);
    var origin = selected ? rowPoint(f, selected) : pa.clone().add(pb).multiplyScalar(0.5);
    if (j.valid || j.penetrating) addArrow(selected ? selected.ref_normal : j.normal, origin, arrowLength(j.penetrating ? j.depth : 0, r), 0x1a9a3a, 1.8);
    addDot(pa, 0x7b3fb0, dot * 0.8); addDot(pb, 0x7b3fb0, dot * 0.8);
    if (!j.penetrating) addLine([pa, pb], 0x7b3fb0, false);
    if (r.friction && $('impulses').checked) drawFriction(f, r);
  });
  f.contacts.forEach(function (c) {
    if (c.point_b) {  // the engine's second witness point: B takes the row's impulse there
      var q = v3(c.point_b);
      addDot(q, 0xf08c00, dot * (c === selected ? 1 : 0.8));
      addLine([rowPoint(f, c), q], 0xf08c00, false);
    }
    if (c === selected) return;
    var p = rowPoint(f, c);
    addArrow(c.normal, p, arrowLength(c.depth, c), 0x1f3f9f, 1);
    addDot(p, 0x1f3f9f, dot);
  });
  if (selected) {  // last: over the reference's wider arrow
    var sp = rowPoint(f, selected);
    addArrow(selected.normal, sp, arrowLength(selected.depth, selected), 0xd01f1f, 1);
    addDot(sp, 0xd01f1f, dot);
  }
  var shown = selected || selRef;
  $('scale').textContent = shown ? 'arrows of pair (' + shown.a + ', ' + shown.b + '): length ' + f4(stub) +
    ' m + depth x ' + f4(depthScale(shown)) + ' (its deepest ' + f4(maxDepth[key(shown)] || 0) +
    ' m over the window); impulses x ' + f4(impulseScale(shown)) + ' m per kg m/s; each pair its own scales' : '';
  var t = [];
  if (selected) {
    t.push('pair (' + selected.a + ', ' + selected.b + '), frame ' + f.frame);
    t.push('engine normal   ' + fv(selected.normal));
    t.push('engine depth    ' + f4(selected.depth) + ' m');
    t.push('engine point    ' + (selected.point ? fv(selected.point) : 'none (drawn at the AABBs\' overlap)'));
    if (selected.point_b) t.push('engine point B  ' + fv(selected.point_b));
    t.push('J_n, J_t        ' + f4(selected.jn) + ', ' + f4(selected.jt) + ' kg m/s');
    if (selected.jt3) t.push('J_t vector      ' + fv(selected.jt3) + ' kg m/s');
  }
  if (selRef) {
    var j = selRef.judged;
    if (!selected) t.push('pair (' + selRef.a + ', ' + selRef.b + '), frame ' + f.frame + ': no contact row');
    t.push('reference       ' + selRef.judge + (j.valid ? '' : ' (no usable answer)'));
    t.push('ref normal      ' + fv(selected ? selected.ref_normal : j.normal));
    if (selected) t.push('angle           ' + f4(selected.angle_deg) + ' deg');
    t.push(j.penetrating ? 'ref depth       ' + f4(j.depth) + ' m' + (j.depth_upper_bound ? ' (upper bound)' : '')
                         : 'ref distance    ' + f4(j.distance) + ' m');
    t.push('ref points      ' + fv(j.point_a) + ' / ' + fv(j.point_b));
    if (selRef.sat_accepted) t.push('SAT axes within ' + f4(selRef.sat_epsilon) + ' m of the minimum: ' + selRef.sat_accepted.length);
    if (selRef.judge === 'AABB') t.push('shapes\' ref     ' + selRef.shapes.kind + ' ' + fv(selRef.shapes.normal) +
      (selRef.shapes.penetrating ? ' depth ' + f4(selRef.shapes.depth) : ' distance ' + f4(selRef.shapes.distance)) + ' m');
  }
  if (selRef && selRef.friction) {
    var fr = selRef.friction;
    t.push('friction        rule ' + fr.rule + ', ' + fr.rows + ' row' + (fr.rows === 1 ? '' : 's') + ' of the pair');
    t.push((fr.rule === 'jt3' ? '|sum jt3|       ' : 'sum |jt|        ') + f4(fr.jt_sum) + ' kg m/s');
    t.push('cone mu x jn    ' + f4(fr.mu) + ' x ' + f4(fr.jn_sum) + ' = ' + f4(fr.cone) + ' kg m/s');
    if (fr.ratio !== null) t.push('ratio           ' + f4(fr.ratio) + 'x the cone (' + (fr.ratio > 1 ? 'outside' : 'inside') + ')');
  } else if (selRef && D.impulses !== 'complete') {
    t.push('friction        not drawn: the trace\'s impulses are ' + D.impulses);
  }
  if (!selected && !selRef) {
    if (!D.has_contact_rows) t.push('this trace has no contact rows (octocd run --contacts writes them)');
    else t.push('no contact row among the bodies drawn in frame ' + f.frame +
      (D.first_contact_frame > 0 ? ' (the trace\'s first contact row: frame ' + D.first_contact_frame + ')' : ''));
  }
  if (f.rows_not_drawn) t.push(f.rows_not_drawn + ' more rows not drawn (cap)');
  if (f.pairs_without_reference) t.push(f.pairs_without_reference + ' pairs without a reference (cap)');
  $('figures').textContent = t.join('\n');
  requestRender();
}

slider.addEventListener('input', function () { show(+slider.value, false); });
pick.addEventListener('change', function () { draw(D.frames[+slider.value]); });
$('boxes').checked = item.kind === 'none';
// The impulses over the normals: on, but on a page of another row's failure (a normal's
// angle, a depth), where they would cover the normals that failed.
$('impulses').checked = !D.failure || D.failure.row === 'friction';
$('impulses').addEventListener('change', function () { draw(D.frames[+slider.value]); });
$('boxes').addEventListener('change', function () {
  D.bodies.forEach(function (b, k) { bodies[k].helper.visible = b.item || $('boxes').checked; });
  requestRender();
});
function resize() {
  var wh = viewSize();
  renderer.setSize(wh[0], wh[1]);
  camera.aspect = wh[0] / Math.max(wh[1], 1); camera.updateProjectionMatrix();
  requestRender();
}
window.addEventListener('resize', resize);
$('toggle').addEventListener('click', function () {
  var c = document.body.classList.toggle('collapsed');
  $('toggle').innerHTML = c ? '&#9654;' : '&#9664;';
  resize();
});
show(+slider.value, false);
renderer.render(scene, camera);
document.body.setAttribute('data-status', window.octocdErrors.length ? 'error' : 'drawn');
})();
</script>
</body></html>
)HTML";
  std::string out;
  out.reserve(js.size() + json.size() + 20000);
  out += head;
  out += title;
  out += style;
  out += js;
  out += between;
  out += json;
  out += tail;
  return out;
}

}  // namespace octocd::detail
