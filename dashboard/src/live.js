// The live page: the WebSocket stream of solved frames drawn by FaceView, the status
// facecapd sends once a second in the counters and the graph, and the controls.
import { act, call, fmt, formatSeconds, readOnly, show, startSession, streamUrl } from './api.js';
import { FaceView, yawPitchRoll } from './face_view.js';
import { SolveGraph } from './graph.js';

// The display rate asked of facecapd: the stream sends at most this many frames a second.
const kDisplayRateHz = 30;

const $ = (id) => document.getElementById(id);
const view = new FaceView($('face'));
const graph = new SolveGraph($('graph'), $('graph-legend'));
let framesSeen = 0;

function connect() {
  const socket = new WebSocket(streamUrl(`rate=${kDisplayRateHz}&vertices=1`));
  socket.onopen = () => ($('connection').textContent = '');
  socket.onmessage = (event) => {
    const message = JSON.parse(event.data);
    if (message.type === 'schema') {
      view.setSchema(message);
      $('rig').textContent = `${message.rig} (${message.rig_units})`;
    } else if (message.type === 'frame') {
      onFrame(message);
    } else if (message.type === 'status') {
      onStatus(message.status);
    }
  };
  socket.onclose = () => {
    $('connection').textContent = 'stream closed: reconnecting...';
    $('quality').className = 'quality unknown';
    $('quality').textContent = 'no stream';
    // A session that ended (logout, expiry) sends this page to the login page.
    setTimeout(() => call('/session').then(connect, () => setTimeout(connect, 1000)), 1000);
  };
}

function onFrame(frame) {
  const drawn = view.update(frame);
  if (drawn) $('vertex-count').textContent = String(drawn);
  framesSeen += 1;
  document.body.dataset.frames = String(framesSeen);
  graph.addFrame(performance.now() / 1000, frame.stage_us);
  const [yaw, pitch, roll] = yawPitchRoll(frame.head.rotation_wxyz);
  $('yaw').textContent = fmt(yaw);
  $('pitch').textContent = fmt(pitch);
  $('roll').textContent = fmt(roll);
  const t = frame.telemetry;
  $('markers-used').textContent = `${t.markers_used} / ${t.markers_expected}`;
  $('folded').title = `this frame: ${t.folded_triangles ?? 0} folded triangles, largest edge stretch ${fmt(t.max_edge_stretch_mm ?? 0, 1)} mm`;
}

// The calibration's markers missing over the last window, by region, and the noisiest.
function showMarkers(markers) {
  const missing = markers.filter((m) => m.missing);
  const byRegion = new Map();
  for (const m of missing) byRegion.set(m.region, [...(byRegion.get(m.region) ?? []), m.label]);
  $('missing-markers').textContent = missing.length
    ? [...byRegion].map(([region, labels]) => `${region}: ${labels.join(', ')}`).join('\n')
    : 'none';
  $('missing-markers').classList.toggle('missing', missing.length > 0);
  document.body.dataset.missingMarkers = missing.map((m) => m.label).join(',');
  const noisy = markers.filter((m) => m.noise_mm !== null).sort((a, b) => b.noise_mm - a.noise_mm).slice(0, 3);
  $('noisiest-markers').textContent = noisy.map((m) => `${m.label} ${fmt(m.noise_mm, 2)} mm`).join(', ') || '-';
}

// The shapes the markers cannot observe: the solve leaves them at 0.
function showUnobserved(shapes, total) {
  $('unobserved-count').textContent = `${shapes.length} of ${total}`;
  $('unobserved-shapes').textContent = shapes.length ? shapes.join(', ') : 'every shape is observed';
}

function onStatus(s) {
  const w = s.window;
  const quality = $('quality');
  quality.className = `quality ${w.quality || 'unknown'}`;
  quality.textContent = w.quality || 'unknown';
  $('quality-reasons').textContent = (w.quality_reasons ?? []).join('; ');
  view.setCalibratedMarkers(w.markers);
  showMarkers(w.markers ?? []);
  showUnobserved(s.calibration.unobserved_shapes ?? [], s.rig.shapes);
  $('source').textContent = `${s.source.description} (${fmt(s.source.rate_hz, 0)} Hz)`;
  $('actor').textContent = s.actor || '(none: the configured calibration)';
  $('calibration').textContent = `${s.calibration.source} · ${s.calibration.markers} markers` +
    (s.calibration.head_stabilised ? ' · head stabilised' : '');
  $('solver').textContent = `${s.solver} · loop ${fmt(s.loop.rate_hz, 0)} Hz`;
  const flagged = s.totals.flagged_frames ?? {};
  $('held').textContent = String((flagged.head_pose_held ?? 0) + (flagged.too_few_markers ?? 0));
  $('held').title = `head pose held ${flagged.head_pose_held ?? 0}, face held ${flagged.too_few_markers ?? 0} (since the start); ` +
    `this window: head ${fmt(w.head_held_fraction * 100)}%, face ${fmt(w.face_held_fraction * 100)}%`;
  $('folded').textContent = `${flagged.folded ?? 0} / ${flagged.inconsistent_marker ?? 0}`;
  $('missed').textContent = String(s.totals.missed_deadlines);
  $('missed').title = `${w.missed_deadlines} in the last ${fmt(w.seconds)} s`;
  $('latency').textContent = `${fmt(w.latency_ms.p50, 2)} / ${fmt(w.latency_ms.p99, 2)}`;
  $('fps').textContent = fmt(w.solved_fps);
  $('residual').textContent = fmt(w.residual_mm.p95, 2);
  graph.setFps(w.solved_fps);
  showRecording(s.recording);
}

// ------------------------------------------------------------------ recording

function showRecording(r) {
  $('record-start').disabled = r.active || readOnly();
  $('record-stop').disabled = !r.active || readOnly();
  $('record-length').textContent = r.active ? `REC ${formatSeconds(r.seconds)} · ${r.frames_written} frames · ${r.take}` : '';
}

$('record-start').onclick = () =>
  act($('record-start'), $('record-message'), async () => {
    // No take: the scene and shot's next number, chosen by facecapd.
    const body = {};
    if ($('take').value.trim()) body.take = $('take').value.trim();
    if ($('scene').value.trim()) body.scene = $('scene').value.trim();
    if ($('shot').value.trim()) body.shot = $('shot').value.trim();
    if ($('notes').value.trim()) body.notes = $('notes').value.trim();
    const started = await call('/record/start', body);
    showRecording({ active: true, seconds: 0, frames_written: 0, take: started.take });
    $('take').value = '';
    return `recording take ${started.take} to ${started.file}`;
  });

$('record-stop').onclick = () =>
  act($('record-stop'), $('record-message'), async () => {
    const stopped = await call('/record/stop', {});
    showRecording({ active: false });
    $('record-message').dataset.file = stopped.file;
    return `saved ${stopped.file}: ${fmt(stopped.seconds)} s, ${stopped.solved_frames} solved frames` +
      (stopped.dropped ? `, ${stopped.dropped} dropped` : '');
  });

// ------------------------------------------------------------------ actors

async function loadActors() {
  const list = await call('/actors');
  const select = $('actors');
  select.replaceChildren(...list.actors.map((a) => {
    const option = document.createElement('option');
    option.value = a.name;
    option.disabled = !a.usable;
    option.textContent = a.usable ? `${a.name} (${a.markers} markers)` : `${a.name}: unusable`;
    option.title = a.error ?? a.calibrated_from ?? '';
    option.selected = a.name === list.current;
    return option;
  }));
  if (!list.actors.length) select.append(new Option(`no profiles in ${list.directory}`, '', true, true));
  return list;
}

$('actors-refresh').onclick = () => act($('actors-refresh'), $('actor-message'), async () => {
  const list = await loadActors();
  return `${list.actors.length} profiles in ${list.directory}`;
});

function describeSwap(answer) {
  return `actor ${answer.actor}: ${answer.markers} markers (${answer.markers_in_source} in the source), ` +
    `built in ${fmt(answer.build_seconds, 2)} s`;
}

$('actor-switch').onclick = () => act($('actor-switch'), $('actor-message'), async () => {
  if (!$('actors').value) throw new Error('choose a profile first');
  return describeSwap(await call('/actor', { name: $('actors').value }));
});

$('profile-load').onclick = () => act($('profile-load'), $('actor-message'), async () => {
  if (!$('profile-file').value.trim()) throw new Error('type the path of a profile file on the box');
  return describeSwap(await call('/actor', { file: $('profile-file').value.trim() }));
});

// ------------------------------------------------------------------ calibration

$('calibrate').onclick = () => act($('calibrate'), $('calibrate-message'), async () => {
  const body = { seconds: Number($('calibrate-seconds').value) };
  if ($('calibrate-save').value.trim()) body.save = $('calibrate-save').value.trim();
  if (body.save && $('calibrate-replace').checked) body.replace = true;
  show($('calibrate-message'), null, `hold a neutral face for ${body.seconds} s...`);
  $('residual-table').replaceChildren();
  $('calibrate-warnings').textContent = '';
  const c = await call('/calibrate', body);
  const rows = Object.entries(c.marker_residual_mm).sort((a, b) => b[1] - a[1]);
  const table = $('residual-table');
  table.innerHTML = '<tr><th>marker</th><th>residual mm</th></tr>';
  // Residual outliers: their rows marked, the likely cause said above the table.
  const warned = new Set(c.warnings.map((w) => /^marker '([^']*)'/.exec(w)?.[1]));
  for (const [marker, mm] of rows) {
    const row = table.insertRow();
    row.insertCell().textContent = marker;
    row.insertCell().textContent = fmt(mm, 3);
    row.classList.toggle('warning', warned.has(marker));
  }
  $('calibrate-warnings').textContent = c.warnings.map((w) => `⚠ ${w}`).join('\n');
  if (body.save) loadActors().catch((e) => show($('actor-message'), e));
  return `calibrated on frame ${c.neutral_frame} of ${c.frames} (${c.units}): residual median ` +
    `${fmt(c.residual_mm.median, 3)} mm, max ${fmt(c.residual_mm.max, 3)} mm; ${c.markers} markers` +
    (c.profile ? `; saved ${c.profile}` : '') + (c.backup ? ` (the old one kept as ${c.backup})` : '') +
    (c.notes.length ? `\n${c.notes.join('\n')}` : '');
});

startSession().then(() => {
  loadActors().catch((e) => show($('actor-message'), e));
  connect();
}, (e) => show($('record-message'), e));
