// The replay page: facecapd lists its recordings and hands out a recording's solved
// frames (GET /recordings, GET /recordings/frames); the page scrubs through them and plays
// them back at the recorded rate, drawn by the live view's FaceView.
import { act, call, fmt, formatSeconds, show, startSession } from './api.js';
import { FaceView, yawPitchRoll } from './face_view.js';

// Playback shows at most this many frames a second, fetched this many at a time.
const kDisplayRateHz = 30;
const kBatchFrames = 30;

const $ = (id) => document.getElementById(id);
const view = new FaceView($('face'));
let recording = null;  // the chosen recording's listing entry, plus rate_hz and total
let playing = false;
let scrubbing = null;  // the frame a scrub asked for while another request was out
let fetching = false;

function frames(first, count, step = 1) {
  const query = new URLSearchParams({ name: recording.name, first, count, step });
  return call(`/recordings/frames?${query}`);
}

function draw(frame, index) {
  const drawn = view.update(frame);
  $('vertex-count').textContent = drawn ? String(drawn) : '-';
  $('frame-no').textContent = `${index + 1} / ${recording.total} (#${frame.frame_no})`;
  $('frame-time').textContent = formatSeconds(index / (recording.rate_hz || 1));
  $('timecode').textContent = frame.timecode ?? '-';
  const [yaw, pitch, roll] = yawPitchRoll(frame.head.rotation_wxyz);
  $('yaw').textContent = fmt(yaw);
  $('pitch').textContent = fmt(pitch);
  $('roll').textContent = fmt(roll);
  $('solve-us').textContent = fmt(frame.solve_us, 0);
  $('markers-used').textContent = `${frame.telemetry.markers_used}`;
  $('scrub').value = String(index);
  const rate = recording.rate_hz || 1;
  $('position').textContent = `${fmt(index / rate)} s of ${fmt(recording.total / rate)} s`;
  document.body.dataset.replayFrame = String(index);
}

async function open(entry) {
  stop();
  recording = { ...entry };
  const first = await frames(0, 1);
  recording.rate_hz = first.rate_hz;
  recording.total = first.solved_frames;
  view.setSchema(first.schema);
  $('rig').textContent = `${first.schema.rig} (${first.schema.rig_units})`;
  $('vertices-from').textContent = {
    recorded: 'mesh as recorded',
    blend: 'mesh: the rig\'s blend of the recorded weights',
    none: 'no mesh (recorded on another rig)',
  }[first.vertices_from];
  $('scrub').max = String(recording.total - 1);
  $('scrub').disabled = false;
  $('play').disabled = false;
  $('replay-title').textContent = `${entry.name}: ${slate(entry)}, actor ${entry.actor || '-'}, ` +
    `${fmt(entry.seconds)} s at ${fmt(first.rate_hz, 0)} Hz`;
  $('replay-notes').textContent = entry.notes ? `notes: ${entry.notes}` : '';
  draw(first.frames[0], 0);
}

// One frame for the slider, the newest asked for when several moves come in quick turn.
async function scrubTo(index) {
  scrubbing = index;
  if (fetching) return;
  fetching = true;
  try {
    while (scrubbing !== null) {
      const at = scrubbing;
      scrubbing = null;
      draw((await frames(at, 1)).frames[0], at);
    }
    show($('replay-message'), null);
  } catch (e) {
    show($('replay-message'), e);
  } finally {
    fetching = false;
  }
}

function stop() {
  playing = false;
  $('play').textContent = '▶ Play';
}

// Plays from the slider's frame at the recorded rate, kDisplayRateHz frames a second.
async function play() {
  playing = true;
  $('play').textContent = '❚❚ Pause';
  const step = Math.max(1, Math.round((recording.rate_hz || kDisplayRateHz) / kDisplayRateHz));
  const interval = (1000 * step) / (recording.rate_hz || kDisplayRateHz);
  let index = Number($('scrub').value);
  if (index >= recording.total - 1) index = 0;
  const started = performance.now() - (index / step) * interval;
  try {
    while (playing && index < recording.total) {
      const batch = await frames(index, kBatchFrames, step);
      for (const [k, frame] of batch.frames.entries()) {
        if (!playing) return;
        const due = started + ((index + k * step) / step) * interval;
        const wait = due - performance.now();
        if (wait > 0) await new Promise((resolve) => setTimeout(resolve, wait));
        draw(frame, index + k * step);
      }
      index += batch.frames.length * step;
    }
    show($('replay-message'), null, 'played to the end');
  } catch (e) {
    show($('replay-message'), e);
  } finally {
    stop();
  }
}

$('play').onclick = () => (playing ? stop() : play());
$('scrub').oninput = () => {
  stop();
  scrubTo(Number($('scrub').value));
};

// "scene 12, shot 3, take 1" with the fields the take has.
function slate(entry) {
  const parts = [['scene', entry.scene], ['shot', entry.shot], ['take', entry.take]].filter(([, v]) => v);
  return parts.length ? parts.map(([k, v]) => `${k} ${v}`).join(', ') : 'no slate';
}

async function list() {
  const answer = await call('/recordings');
  $('recordings-directory').textContent = `${answer.recordings.length} in ${answer.directory}`;
  const table = $('recordings');
  table.replaceChildren();
  for (const entry of answer.recordings) {
    const row = table.insertRow();
    row.dataset.name = entry.name;
    row.insertCell().textContent = entry.name;
    if (entry.error) {
      const cell = row.insertCell();
      cell.colSpan = 3;
      cell.textContent = entry.error;
      cell.classList.add('error');
      continue;
    }
    row.insertCell().textContent = slate(entry);
    row.insertCell().textContent = `${fmt(entry.seconds)} s`;
    row.title = entry.notes || '';
    row.insertCell().textContent = entry.solved_frames ? `${entry.solved_frames} solved` : 'markers only';
    if (!entry.solved_frames) continue;
    row.onclick = async () => {
      for (const r of table.rows) r.classList.toggle('selected', r === row);
      try {
        await open(entry);
        show($('replay-message'), null);
      } catch (e) {
        show($('replay-message'), e);
      }
    };
  }
  return answer;
}

$('recordings-refresh').onclick = () => act($('recordings-refresh'), $('replay-message'), async () => {
  await list();
});
startSession().then(list).catch((e) => show($('replay-message'), e));
