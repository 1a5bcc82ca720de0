#include "ar/debug/viewer_assets.h"

namespace arreg::debug {

const char kViewerIndexHtml[] = R"HTML(<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>arreg debug viewer</title>
<link rel="icon" href="data:,">
<link rel="stylesheet" href="viewer.css">
<script src="data/meta.js"></script>
</head>
<body>
<header>
  <h1 id="title">arreg debug viewer</h1>
  <div id="controls">
    <button id="prev" title="previous frame (Left arrow)">&#9664;</button>
    <button id="play" title="play / pause (Space)">play</button>
    <button id="next" title="next frame (Right arrow)">&#9654;</button>
    <input id="slider" type="range" min="0" max="0" value="0" step="1">
    <span>frame <b id="frame-index">-</b> / <span id="frame-last">-</span></span>
  </div>
  <div id="layers"></div>
</header>
<main>
  <div id="stage"><canvas id="view" width="640" height="480"></canvas></div>
  <aside>
    <div id="status"></div>
    <h2>Frame</h2>
    <table id="numbers"></table>
    <h2>Selected feature</h2>
    <div id="feature-info">click a feature in the image</div>
    <svg id="mu-plot" width="320" height="140" viewBox="0 0 320 140"></svg>
    <div class="legend">pairs: <span class="ramp"></span> mu / (tau &times; mean mu) from 0 to 1;
      thick red: outlier pairs; magenta: cut polyline (dashed: extended), cut surface;
      blue &times;: targets p<sup>1</sup>; yellow: springs p<sup>t</sup>&ndash;p<sup>1</sup></div>
    <div class="help">keys: &larr; &rarr; step, Space play/pause, Home / End</div>
  </aside>
</main>
<script src="viewer.js"></script>
</body>
</html>
)HTML";

const char kViewerCss[] =
    R"CSS(body { margin: 0; font: 13px sans-serif; background: #1e1e1e; color: #ddd; }
header { padding: 6px 10px; background: #2a2a2a; }
h1 { font-size: 15px; margin: 0 0 4px 0; }
h2 { font-size: 13px; margin: 10px 0 4px 0; color: #aaa; }
#controls { display: flex; align-items: center; gap: 8px; }
#slider { flex: 1; }
#layers label { margin-right: 10px; white-space: nowrap; }
main { display: flex; gap: 10px; padding: 10px; }
#stage { flex: 1; min-width: 0; }
#view { width: 100%; height: auto; background: #000; cursor: crosshair; }
aside { width: 340px; }
table { border-collapse: collapse; width: 100%; }
td { padding: 1px 4px; border-bottom: 1px solid #333; }
td.v { text-align: right; font-family: monospace; }
#mu-plot { background: #111; margin-top: 4px; }
.legend, .help { color: #999; margin-top: 8px; }
.ramp { display: inline-block; width: 60px; height: 8px;
        background: linear-gradient(to right, #0000ff, #00ff00, #ff0000); }
#status { color: #f88; }
)CSS";

const char kViewerJs[] = R"JS('use strict';
// arreg debug viewer: frame records are small scripts loaded on demand (file:// forbids fetch).
(function () {
  const meta = window.ARREG_META;
  const frames = meta.frames;
  const LAYERS = [['image', 'image', true], ['features', 'features', true],
    ['targets', 'targets', true], ['springs', 'springs', true], ['pairs', 'neighbour graph (mu)', false],
    ['outliers', 'outliers', true], ['cut', 'cut points / polyline', true], ['mesh', 'mesh wireframe', false],
    ['internal', 'internal structures', false], ['instruments', 'instruments', true],
    ['track', 'selected track', true]];
  const CACHE_FRAMES = 48;
  const records = new Map(), waiting = new Map(), images = new Map(), topologies = new Map();
  const topoWaiting = new Map();
  let index = 0, token = 0, playing = false, timer = null, busy = false;
  let selected = null, tracks = null, tracksWaiting = [];
  let current = null;  // {rec, img, topo}

  const $ = (id) => document.getElementById(id);
  const canvas = $('view'), ctx = canvas.getContext('2d');
  const pad = (n) => String(n).padStart(6, '0');
  const layerOn = (name) => $('layer-' + name).checked;

  function status(text) { $('status').textContent = text; }
  function loadScript(src, fail) {
    const s = document.createElement('script');
    s.src = src;
    s.onerror = fail;
    s.onload = () => s.remove();
    document.head.appendChild(s);
  }
  function remember(map, key, value, limit) {
    map.set(key, value);
    while (map.size > limit) map.delete(map.keys().next().value);
  }

  window.arregFrame = function (n, rec) {
    remember(records, n, rec, CACHE_FRAMES);
    const cbs = waiting.get(n) || [];
    waiting.delete(n);
    cbs.forEach((cb) => cb(rec));
  };
  window.arregTopology = function (k, topo) {
    topologies.set(k, topo);
    const cbs = topoWaiting.get(k) || [];
    topoWaiting.delete(k);
    cbs.forEach((cb) => cb(topo));
  };
  window.arregTracks = function (data) {
    tracks = data;
    const cbs = tracksWaiting;
    tracksWaiting = [];
    cbs.forEach((cb) => cb());
  };

  function withRecord(n, cb) {
    if (records.has(n)) return cb(records.get(n));
    if (waiting.has(n)) return waiting.get(n).push(cb);
    waiting.set(n, [cb]);
    loadScript('data/frame_' + pad(n) + '.js', () => { waiting.delete(n); status('no data for frame ' + n); });
  }
  function withImage(n, cb) {
    if (images.has(n) && images.get(n).complete) {
      const done = images.get(n);
      return cb(done.naturalWidth > 0 ? done : null);  // a broken image cannot be drawn
    }
    const im = images.get(n) || new Image();
    im.addEventListener('load', () => cb(im), { once: true });
    im.addEventListener('error', () => cb(null), { once: true });
    if (!images.has(n)) {
      remember(images, n, im, CACHE_FRAMES);
      im.src = 'frames/' + pad(n) + '.jpg';
    }
  }
  function withTopology(k, cb) {
    if (k === undefined || k < 0) return cb(null);
    if (topologies.has(k)) return cb(topologies.get(k));
    if (topoWaiting.has(k)) return topoWaiting.get(k).push(cb);
    topoWaiting.set(k, [cb]);
    loadScript('data/topology_' + pad(k) + '.js', () => { topoWaiting.delete(k); cb(null); });
  }
  function withTracks(cb) {
    if (tracks) return cb();
    tracksWaiting.push(cb);
    if (tracksWaiting.length === 1) loadScript('data/tracks.js', () => status('no track data'));
  }

  function show(i) {
    index = Math.max(0, Math.min(frames.length - 1, i));
    const n = frames[index];
    $('slider').value = index;
    $('frame-index').textContent = n;
    const mine = ++token;
    busy = true;
    withRecord(n, (rec) => withImage(n, (im) => withTopology(rec.topology, (topo) => {
      if (mine !== token) return;
      current = { rec: rec, img: im, topo: topo };
      busy = false;
      draw();
      canvas.dataset.frame = String(rec.frame);  // the frame on screen (for tests and tools)
      numbers(rec);
      plotMu();
    })));
    if (index + 1 < frames.length) withRecord(frames[index + 1], () => {});
  }

  function colourRatio(r) {
    r = Math.max(0, Math.min(1, r));
    if (r < 0.5) { const t = r / 0.5; return 'rgb(0,' + Math.round(255 * t) + ',' + Math.round(255 * (1 - t)) + ')'; }
    const t = (r - 0.5) / 0.5;
    return 'rgb(' + Math.round(255 * t) + ',' + Math.round(255 * (1 - t)) + ',0)';
  }
  function line(a, b, colour, width) {
    ctx.strokeStyle = colour; ctx.lineWidth = width;
    ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
  }
  function polyline(pts, colour, width, dash) {
    ctx.setLineDash(dash || []);
    ctx.strokeStyle = colour; ctx.lineWidth = width;
    ctx.beginPath();
    let pen = false;
    for (const p of pts) {
      if (!p) { pen = false; continue; }
      if (pen) ctx.lineTo(p[0], p[1]); else ctx.moveTo(p[0], p[1]);
      pen = true;
    }
    ctx.stroke();
    ctx.setLineDash([]);
  }
  function wire(px, edges, colour) {
    if (!px || !edges) return;
    ctx.strokeStyle = colour; ctx.lineWidth = 0.7;
    ctx.beginPath();
    for (let e = 0; e + 1 < edges.length; e += 2) {
      const a = edges[e], b = edges[e + 1];
      if (px[2 * a] === null || px[2 * b] === null || px[2 * a] === undefined || px[2 * b] === undefined) continue;
      ctx.moveTo(px[2 * a], px[2 * a + 1]); ctx.lineTo(px[2 * b], px[2 * b + 1]);
    }
    ctx.stroke();
  }

  function draw() {
    if (!current) return;
    const rec = current.rec, im = current.img, topo = current.topo;
    const w = meta.width || (im ? im.naturalWidth : 640), h = meta.height || (im ? im.naturalHeight : 480);
    if (canvas.width !== w) canvas.width = w;
    if (canvas.height !== h) canvas.height = h;
    ctx.fillStyle = '#000'; ctx.fillRect(0, 0, w, h);
    if (im && layerOn('image')) ctx.drawImage(im, 0, 0, w, h);
    if (topo && layerOn('mesh')) wire(rec.surface_px, topo.surface_edges, 'rgba(200,200,200,0.6)');
    if (topo && layerOn('internal'))
      rec.internal.forEach((s, k) => wire(s.px, topo.internal_edges[k], 'rgba(200,120,255,0.8)'));
    const byId = new Map();
    rec.features.forEach((f) => byId.set(f.id, f));
    const det = rec.detection;
    if (det && (layerOn('pairs') || layerOn('outliers'))) {
      for (const p of det.pairs) {
        const a = byId.get(p[0]), b = byId.get(p[1]);
        if (!a || !b) continue;
        if (p[3] && layerOn('outliers')) line(a.px, b.px, '#ff2020', 3);
        else if (!p[3] && layerOn('pairs')) line(a.px, b.px, colourRatio(det.threshold > 0 ? p[2] / det.threshold : 0), 1);
      }
    }
    if (layerOn('instruments') && rec.instruments) {
      ctx.strokeStyle = '#ff8c00'; ctx.lineWidth = 1.5;
      for (const o of rec.instruments) {
        ctx.beginPath();
        for (let k = 0; k + 1 < o.length; k += 2) (k ? ctx.lineTo : ctx.moveTo).call(ctx, o[k], o[k + 1]);
        ctx.closePath(); ctx.stroke();
      }
    }
    for (const f of rec.features) {
      if (layerOn('instruments') && f.status === 'instrument') {
        ctx.beginPath(); ctx.arc(f.px[0], f.px[1], 5, 0, 2 * Math.PI);
        ctx.strokeStyle = '#ff8c00'; ctx.lineWidth = 1; ctx.stroke();
      }
      if (layerOn('springs') && f.spring_active && f.target_px && f.model_px) line(f.model_px, f.target_px, '#ffe600', 1);
      if (layerOn('targets') && f.target_px) {
        const t = f.target_px;
        line([t[0] - 3, t[1] - 3], [t[0] + 3, t[1] + 3], '#0080ff', 1.5);
        line([t[0] - 3, t[1] + 3], [t[0] + 3, t[1] - 3], '#0080ff', 1.5);
      }
      if (layerOn('features')) {
        ctx.beginPath(); ctx.arc(f.px[0], f.px[1], 3, 0, 2 * Math.PI);
        const colour = f.alive ? '#00dc00' : (f.lift === 'not-attached' ? '#dc3c3c' : '#969696');
        if (f.alive) { ctx.fillStyle = colour; ctx.fill(); } else { ctx.strokeStyle = colour; ctx.lineWidth = 1; ctx.stroke(); }
      }
    }
    if (layerOn('cut')) {
      const cs = rec.cut_surface;
      if (cs) {
        ctx.fillStyle = 'rgba(255,0,255,0.25)';
        for (let k = 0; k + 2 < cs.faces.length; k += 3) {
          const v = [cs.faces[k], cs.faces[k + 1], cs.faces[k + 2]];
          if (v.some((i) => cs.px[2 * i] === null)) continue;
          ctx.beginPath();
          ctx.moveTo(cs.px[2 * v[0]], cs.px[2 * v[0] + 1]);
          ctx.lineTo(cs.px[2 * v[1]], cs.px[2 * v[1] + 1]);
          ctx.lineTo(cs.px[2 * v[2]], cs.px[2 * v[2] + 1]);
          ctx.closePath(); ctx.fill();
        }
      }
      if (det) {
        polyline(det.extended_polyline_px, '#ff00ff', 1, [5, 4]);
        polyline(det.polyline_px, '#ff00ff', 2.5);
        ctx.fillStyle = '#ff00ff';
        for (const p of det.polyline_px) if (p) { ctx.beginPath(); ctx.arc(p[0], p[1], 4, 0, 2 * Math.PI); ctx.fill(); }
        for (const c of det.new_cut_points) if (c.px) {
          ctx.strokeStyle = '#ffff00'; ctx.lineWidth = 2;
          ctx.beginPath(); ctx.arc(c.px[0], c.px[1], 7, 0, 2 * Math.PI); ctx.stroke();
        }
      }
    }
    if (selected !== null) {
      const f = byId.get(selected);
      if (tracks && layerOn('track')) {
        const t = tracks[selected];
        if (t) polyline(t.f.map((_, k) => [t.x[k], t.y[k]]), '#00ffff', 1.5);
      }
      if (f) { ctx.strokeStyle = '#00ffff'; ctx.lineWidth = 2; ctx.beginPath(); ctx.arc(f.px[0], f.px[1], 8, 0, 2 * Math.PI); ctx.stroke(); }
    }
  }

  function fmt(v, d) {
    if (v === null || v === undefined) return '-';
    return typeof v === 'number' ? (Number.isInteger(v) ? String(v) : v.toFixed(d === undefined ? 3 : d)) : String(v);
  }
  function numbers(rec) {
    const rows = [['frame', rec.frame], ['time [s]', rec.time_s]];
    const s = rec.stats;
    rows.push(['features alive', s.features_alive], ['lost this frame', s.lost],
      ['spatio-temporal outliers', s.outliers], ['spring mean [mm]', s.spring_length_mean_mm],
      ['spring max [mm]', s.spring_length_max_mm], ['inverted elements', s.inverted_elements],
      ['mechanics', s.mechanics_status]);
    const det = rec.detection;
    if (det) {
      rows.push(['pairs', det.pairs.length], ['outlier pairs / n', det.outliers + ' / ' + det.min_outliers],
        ['mean mu [mm]', det.mean_mu], ['tau', det.tau], ['threshold tau*mean [mm]', det.threshold],
        ['new cut points', det.new_cut_points.length], ['polyline points', det.polyline_px.length],
        ['pairs removed (cut / death) / bridged', det.pairs_removed_by_cut + ' / ' + det.pairs_removed_by_death + ' / ' + det.pairs_bridged],
        ['growth probe pairs / outliers', det.probe_pairs + ' / ' + det.probe_outliers +
          (det.new_cut_points.some((c) => c.probe) ? ' (point inserted)' : '')],
        ['clusters rejected: sliding star / one-sided / star start / unconfirmed start / closing start / no growth / splitting',
          [det.lone_features, det.one_sided_clusters, det.star_starts, det.unconfirmed_starts,
            det.closing_starts, det.refused_points, det.refused_segments].map((v) => (v === undefined ? '-' : v)).join(' / ')]);
      (det.separation_tests || []).forEach((t) => rows.push(['separation test at ' +
        t.initial_mm.map((v) => v.toFixed(1)).join(', ') + ' mm',
        (t.tested ? 'F ' + t.statistic.toFixed(1) + ' / ' + t.threshold.toFixed(1) +
          ' (one left out ' + t.robust_statistic.toFixed(1) + '), opening ' + t.opening_mm.toFixed(2) +
          ' mm, sides ' + t.features_side.join('/') : 'too few features') +
        (t.separated ? ': separated' : '')]));
    } else {
      rows.push(['cut detection', 'off']);
    }
    rec.cut_events.forEach((e) => rows.push(['cut event', e.status +
      (e.status === 'cut' ? ' (' + e.configuration + ', depth ' + e.depth_fraction + ', +' + e.new_vertices + ' V' +
        (e.welded_vertices ? ', ' + e.welded_vertices + ' V of debris welded' : '') +
        (e.internal_cap_faces ? ', ' + e.internal_cap_faces + ' internal cap faces' : '') +
        (e.internal_triangles_removed ? ', ' + e.internal_triangles_removed + ' internal faces deleted' : '') + ')' : '') +
      (e.message ? ': ' + e.message : '')]));
    if (rec.model) rows.push(['model V / T', rec.model.vertices + ' / ' + rec.model.tetrahedra]);
    for (const k of Object.keys(rec.ms)) rows.push([k + ' [ms]', rec.ms[k]]);
    const table = $('numbers');
    table.textContent = '';
    for (const [k, v] of rows) {
      const tr = document.createElement('tr');
      const a = document.createElement('td'); a.textContent = k;
      const b = document.createElement('td'); b.className = 'v'; b.textContent = fmt(v);
      tr.appendChild(a); tr.appendChild(b); table.appendChild(tr);
    }
  }

  function plotMu() {
    const svg = $('mu-plot');
    while (svg.firstChild) svg.removeChild(svg.firstChild);
    if (selected === null || !tracks || !tracks[selected]) return;
    const t = tracks[selected];
    const W = 320, H = 140, L = 40, B = 18;
    let top = 0;
    t.mu.forEach((m, k) => { if (m !== null) top = Math.max(top, m); if (t.thr[k] !== null) top = Math.max(top, t.thr[k]); });
    if (!(top > 0)) top = 1;
    const f0 = frames[0], f1 = Math.max(frames[frames.length - 1], f0 + 1);
    const X = (f) => L + (W - L - 6) * (f - f0) / (f1 - f0), Y = (v) => H - B - (H - B - 6) * v / top;
    const ns = 'http://www.w3.org/2000/svg';
    const add = (tag, attrs, text) => {
      const e = document.createElementNS(ns, tag);
      for (const k of Object.keys(attrs)) e.setAttribute(k, attrs[k]);
      if (text !== undefined) e.textContent = text;
      svg.appendChild(e); return e;
    };
    const path = (vals, colour, dash) => {
      let d = '', pen = false;
      vals.forEach((v, k) => {
        if (v === null) { pen = false; return; }
        d += (pen ? 'L' : 'M') + X(t.f[k]).toFixed(1) + ' ' + Y(v).toFixed(1) + ' '; pen = true;
      });
      if (d) add('path', { d: d, fill: 'none', stroke: colour, 'stroke-width': 1.5, 'stroke-dasharray': dash || '' });
    };
    add('line', { x1: L, y1: H - B, x2: W, y2: H - B, stroke: '#666' });
    add('line', { x1: L, y1: 0, x2: L, y2: H - B, stroke: '#666' });
    add('text', { x: 2, y: 12, fill: '#aaa', 'font-size': 10 }, top.toPrecision(3));
    add('text', { x: 2, y: H - B, fill: '#aaa', 'font-size': 10 }, '0');
    add('text', { x: L, y: H - 4, fill: '#aaa', 'font-size': 10 }, 'frame ' + f0);
    add('text', { x: W - 60, y: H - 4, fill: '#aaa', 'font-size': 10 }, 'frame ' + f1);
    path(t.thr, '#ff5050', '4 3');
    path(t.mu, '#4aa3ff');
    const cur = frames[index];
    add('line', { x1: X(cur), y1: 0, x2: X(cur), y2: H - B, stroke: '#ffff00', 'stroke-width': 1 });
    const k = t.f.indexOf(cur);
    const mu = k >= 0 ? t.mu[k] : null, thr = k >= 0 ? t.thr[k] : null;
    $('feature-info').textContent = 'feature ' + selected + ': tracked in ' + t.f.length + ' frames; max mu of its pairs here ' +
      fmt(mu, 4) + ' mm, threshold ' + fmt(thr, 4) + ' mm (blue: max mu, red dashed: tau x mean mu)';
  }

  function select(id) {
    selected = id;
    $('feature-info').textContent = 'feature ' + id + ': loading track...';
    withTracks(() => { draw(); plotMu(); canvas.dataset.selected = String(id); });
  }

  canvas.addEventListener('click', (ev) => {
    if (!current) return;
    const r = canvas.getBoundingClientRect();
    const x = (ev.clientX - r.left) * canvas.width / r.width, y = (ev.clientY - r.top) * canvas.height / r.height;
    let best = null, bestD = 12 * 12;
    for (const f of current.rec.features) {
      const d = (f.px[0] - x) ** 2 + (f.px[1] - y) ** 2;
      if (d < bestD) { bestD = d; best = f.id; }
    }
    if (best !== null) select(best);
  });

  function setPlaying(on) {
    playing = on;
    $('play').textContent = on ? 'pause' : 'play';
    if (timer) { clearInterval(timer); timer = null; }
    if (on) {
      timer = setInterval(() => {
        if (busy) return;
        if (index + 1 >= frames.length) { setPlaying(false); return; }
        show(index + 1);
      }, 1000 / Math.min(30, meta.fps > 0 ? meta.fps : 10));
    }
  }

  function init() {
    if (!meta || !frames.length) { status('no frames recorded'); return; }
    document.title = meta.title + ' - arreg debug viewer';
    $('title').textContent = meta.title;
    $('slider').max = frames.length - 1;
    $('frame-last').textContent = frames[frames.length - 1];
    const box = $('layers');
    for (const [name, label, on] of LAYERS) {
      const l = document.createElement('label');
      const c = document.createElement('input');
      c.type = 'checkbox'; c.id = 'layer-' + name; c.checked = on;
      c.addEventListener('change', draw);
      l.appendChild(c); l.appendChild(document.createTextNode(' ' + label));
      box.appendChild(l);
    }
    $('slider').addEventListener('input', () => show(Number($('slider').value)));
    $('prev').addEventListener('click', () => show(index - 1));
    $('next').addEventListener('click', () => show(index + 1));
    $('play').addEventListener('click', () => setPlaying(!playing));
    document.addEventListener('keydown', (ev) => {
      if (ev.key === 'ArrowRight') show(index + 1);
      else if (ev.key === 'ArrowLeft') show(index - 1);
      else if (ev.key === 'Home') show(0);
      else if (ev.key === 'End') show(frames.length - 1);
      else if (ev.key === ' ') setPlaying(!playing);
      else return;
      ev.preventDefault();
    });
    show(0);
  }
  init();
})();
)JS";

}  // namespace arreg::debug
