// The terminal page's script (page.html): served from the daemon itself,
// as the page's Content-Security-Policy allows no inline script.
//
// One model, one render: everything the page knows (the daemon's status, the
// store's active calibration and history, the contact with the daemon, a
// pending confirmation) is kept in `model`, and `render()` draws the whole
// page from it. The event stream, the status polls and the buttons only
// change the model.
'use strict';
const $ = (id) => document.getElementById(id);

const model = {
  status: null, // the last GET /api/status
  contact: 'connecting', // 'connecting' | 'ok' | 'lost'
  lostSince: null,
  heardAt: 0, // when the daemon was last heard from (a heartbeat, an event, a status)
  active: null, // GET /api/active, or null when none
  history: [], // GET /api/calibrations
  sending: null, // a button's request on its way: 'Abort', 'Calibrate', …
  confirm: null, // {kind: 'accept' | 'rollback', id}
  confirmRun: null, // 'calibration' | 'check': a button that moves the robot, asked first
  message: null, // {text, kind: 'error' | 'ok'}
  statusAt: 0, // when the status was read (for the time so far)
};

// Contact is lost when the daemon has said nothing for this long: two
// heartbeats of its event stream (one a second) missed, and the status polls
// (one a second) unanswered. A request gives up after REQUEST_MS.
const SILENCE_MS = 2200;
const REQUEST_MS = 3000;

const PARAMS = [
  ['alpha_deg', 'α', '°', 'rotation about the vertical'],
  ['beta_deg', 'β', '°', 'pitch'],
  ['gamma_deg', 'γ', '°', 'roll'],
  ['px_mm', 'x', ' mm', 'forward'],
  ['py_mm', 'y', ' mm', 'up'],
  ['pz_mm', 'z', ' mm', 'right'],
];

// ---- the token and the calls that need it --------------------------------

const tokenField = $('token');
tokenField.value = localStorage.getItem('groundcal-token') || '';
$('token-card').open = !tokenField.value;
tokenField.addEventListener('input', () => localStorage.setItem('groundcal-token', tokenField.value.trim()));

// What an error answer means for an operator.
function explain(response, body) {
  const token = tokenField.value.trim();
  if (response.status === 401) {
    $('token-card').open = true;
    return token
      ? 'The token is not right. Copy it again from the robot\'s token file.'
      : 'Type the token first (below): it is in the robot\'s token file.';
  }
  if (response.status === 403 || response.status === 421) {
    return 'The robot refused this page: open it at the robot\'s own address.';
  }
  return (body && body.error) || ('the robot answered ' + response.status);
}

// A request that gives up after `ms`: a daemon that stopped, or a link that
// dropped without closing, must not leave a button waiting for ever.
async function fetchWithin(url, options, ms) {
  const controller = new AbortController();
  const timer = setTimeout(() => controller.abort(), ms || REQUEST_MS);
  try {
    return await fetch(url, { ...(options || {}), signal: controller.signal });
  } finally {
    clearTimeout(timer);
  }
}

// What the page can say when a button's request did not get through: it
// cannot know what the robot does, so it says what it knows.
function notSent(what, timedOut) {
  const running = model.status && model.status.state === 'running';
  return what + ' could not be sent: the robot\'s computer ' + (timedOut ? 'did not answer within ' + (REQUEST_MS / 1000) + ' s.' : 'refused the connection or cannot be reached.')
    + (running ? ' If groundcal has stopped, the robot\'s own watchdog halts the body within 1 s; if only this device\'s link is down, the run goes on. Use the robot\'s emergency stop if anyone is at risk.' : '');
}

// `what` names the button in the words shown when it fails ("Abort").
async function call(method, url, what) {
  const headers = { 'Authorization': 'Bearer ' + tokenField.value.trim(), 'X-Groundcal-Client': 'terminal page' };
  let response;
  let body = {};
  model.sending = what;
  render();
  try {
    response = await fetchWithin(url, { method, headers });
    try { body = await response.json(); } catch (e) { body = {}; }
  } catch (e) {
    model.sending = null;
    model.message = { text: notSent(what, e && e.name === 'AbortError'), kind: 'error' };
    lose();
    return null;
  }
  model.sending = null;
  heard();
  model.message = response.ok ? null : { text: explain(response, body), kind: 'error' };
  if (response.ok) $('token-card').open = false;
  render();
  return response.ok ? body : null;
}

// Calibrate and Check move a legged robot: each asks first, saying for how
// long and to keep clear. Cancel sends nothing.
$('calibrate').onclick = () => { model.confirm = null; model.confirmRun = 'calibration'; render(); };
// A check of the active calibration against the sensor now (the robot holds
// its home stance, or tilts a little with [verify] poses).
$('check').onclick = () => { model.confirm = null; model.confirmRun = 'check'; render(); };
$('confirm-run-no').onclick = () => { model.confirmRun = null; render(); };
$('confirm-run-yes').onclick = async () => {
  const kind = model.confirmRun;
  model.confirmRun = null;
  if (!kind) return;
  const started = kind === 'calibration'
    ? await call('POST', '/api/calibrations', 'Calibrate')
    : await call('POST', '/api/check', 'Check');
  if (started) refresh();
};
// Abort is never pretended: the page says "aborting…" only once the daemon
// has it (the status's `abort`), and says so when it could not be sent.
$('abort').onclick = async () => {
  model.confirmRun = null;
  await call('POST', '/api/calibrations/current/abort', 'Abort');
  refresh();
};
$('accept').onclick = () => {
  const s = model.status;
  if (s && s.result_id) { model.confirm = { kind: 'accept', id: s.result_id }; render(); }
};
$('confirm-no').onclick = () => { model.confirm = null; render(); };
$('confirm-yes').onclick = async () => {
  const c = model.confirm;
  if (!c) return;
  model.confirm = null;
  const url = c.kind === 'accept' ? '/api/calibrations/' + c.id + '/accept' : '/api/rollback/' + c.id;
  const active = await call('POST', url, c.kind === 'accept' ? 'Accept' : 'Roll back');
  if (active) {
    model.active = active;
    const wasActive = model.status && model.status.active;
    model.message = { text: (c.kind === 'accept' ? 'Accepted: ' : wasActive ? 'Rolled back: ' : 'Made active: ') + 'the calibration of ' + madeOn(c.id) + ' is now the active one.', kind: 'ok', activeId: c.id };
    loadStore();
  }
  render();
};

// ---- words and numbers ---------------------------------------------------

function duration(seconds) {
  const s = Math.max(0, Math.round(seconds));
  if (s < 60) return s + ' s';
  return Math.floor(s / 60) + ' min ' + String(s % 60).padStart(2, '0') + ' s';
}
// When a calibration was made, in the device's own time, from the history
// (its id is a time too, in UTC: the fallback).
function madeOn(id) {
  const h = model.history.find((e) => e.id === id);
  if (h && h.created) return when(h.created);
  const m = /^(\d{4})(\d\d)(\d\d)(\d\d)(\d\d)(\d\d)/.exec(id || '');
  return m ? when(m[1] + '-' + m[2] + '-' + m[3] + 'T' + m[4] + ':' + m[5] + ':' + m[6] + 'Z') : (id || '?');
}
// Fills a list element with lines of text.
function list(element, lines) {
  element.innerHTML = '';
  for (const line of lines) { const li = document.createElement('li'); li.textContent = line; element.appendChild(li); }
}
// What an operator can do about each failed check (by its gate), and
// which calibration the robot uses meanwhile.
const TODO = {
  theta_max_deg: 'Make sure the robot stands on flat, firm ground, with nothing on the floor in front of it (boxes, cables, people), then press Calibrate again.',
  e_d_max_mm: 'Make sure the robot stands on flat, firm ground, with nothing on the floor in front of it, and that no foot has slipped; then press Calibrate again.',
  sigma_angle_max_deg: 'Press Calibrate again with nothing moving in view. If it fails the same way, ask a maintainer to check the schedule.',
  sigma_position_max_mm: 'Press Calibrate again with nothing moving in view. If it fails the same way, ask a maintainer to check the schedule.',
  min_poses_used: 'Many poses found no ground: clear the floor in front of the robot, check that the lens is clean and uncovered and that the Kinect points at the floor, then press Calibrate again.',
  min_used_fraction: 'Many poses found no ground: clear the floor in front of the robot, check that the lens is clean and uncovered and that the Kinect points at the floor, then press Calibrate again.',
  depth_scale_max_deviation: 'The depth reads far from the truth: ask a maintainer to check the sensor\'s depth settings.',
  observable: 'The schedule cannot pin the sensor down: ask a maintainer to check it.',
};
function todoFor(result) {
  const lines = [];
  for (const c of result.gate_checks || []) {
    const line = !c.passed && TODO[c.gate];
    if (line && !lines.includes(line)) lines.push(line);
  }
  if ((result.reasons || []).some((r) => /motor/.test(r))) lines.push('The Kinect\'s tilt motor moved during the run: make sure nothing touches the sensor, then press Calibrate again.');
  if (!lines.length) lines.push('Press Calibrate again; if it fails the same way, ask a maintainer.');
  const active = model.status && model.status.active;
  lines.push(active ? 'Meanwhile the robot uses the active calibration, of ' + madeOn(active.id) + '.' : 'Meanwhile the robot uses no calibration from groundcal.');
  return lines;
}

// "about 2 min", "about 10 s": how long the robot will move.
function about(seconds) {
  return seconds >= 90 ? 'about ' + Math.round(seconds / 60) + ' min' : 'about ' + Math.max(1, Math.round(seconds)) + ' s';
}
function when(rfc3339) {
  const t = new Date(rfc3339);
  return isNaN(t) ? (rfc3339 || '?') : t.toLocaleString([], { dateStyle: 'medium', timeStyle: 'medium' });
}
function fixed(value, unit) { return value.toFixed(unit === '°' ? 3 : 1); }
// A σ with two significant digits: 0.0022°, 0.049 mm.
function sig(value) { return value.toPrecision(2); }

// How a result differs from the active calibration, in words: the largest
// change of an angle and of a position.
function changeInWords(mount, active) {
  if (!active || !active.robot_from_sensor) return '';
  let angle = null;
  let shift = null;
  for (const [key, name, unit] of PARAMS) {
    const delta = mount[key] - active.robot_from_sensor[key];
    const slot = { name, delta, unit };
    if (unit === '°') { if (!angle || Math.abs(delta) > Math.abs(angle.delta)) angle = slot; } else if (!shift || Math.abs(delta) > Math.abs(shift.delta)) shift = slot;
  }
  return 'Against the active calibration (of ' + madeOn(active.id) + '): angles differ by up to ' + Math.abs(angle.delta).toFixed(3)
    + '° (' + angle.name + '), positions by up to ' + Math.abs(shift.delta).toFixed(1) + ' mm (' + shift.name + ').';
}

// predicted: the σ `plan` predicted before the robot moved (shown under
// the achieved σ, to compare).
// scale: the result's depth scale ({value, sigma, estimated}), a row of its own.
function valuesTable(table, mount, sigma, active, predicted, scale) {
  table.innerHTML = '';
  const head = table.insertRow();
  // Short headers, the longer words small beneath: at phone width every
  // column must fit.
  for (const [h, under] of [['', ''], ['value', ''], ['±σ', predicted ? '(predicted)' : ''], [active ? 'change' : '', '']]) {
    const th = document.createElement('th'); th.textContent = h;
    if (under) { const small = document.createElement('div'); small.className = 'small'; small.textContent = under; th.appendChild(small); }
    head.appendChild(th);
  }
  for (const [key, name, unit, words] of PARAMS) {
    const row = table.insertRow();
    const label = row.insertCell();
    const small = document.createElement('span'); small.className = 'small'; small.textContent = ' ' + words;
    label.append(name, small);
    row.insertCell().textContent = fixed(mount[key], unit) + unit;
    const sigmaCell = row.insertCell();
    sigmaCell.textContent = sigma ? sig(sigma[key]) + unit : '';
    if (predicted) {
      const small = document.createElement('div'); small.className = 'small predicted';
      small.textContent = '(' + sig(predicted[key]) + unit + ')';
      sigmaCell.appendChild(small);
    }
    const change = active && active.robot_from_sensor ? mount[key] - active.robot_from_sensor[key] : null;
    const shown = change === null ? '' : fixed(Math.abs(change), unit);
    const sign = change === null || Number(shown) === 0 ? '' : (change > 0 ? '+' : '−');
    row.insertCell().textContent = change === null ? '' : sign + shown + unit;
  }
  if (scale && typeof scale.value === 'number') {
    const row = table.insertRow();
    const label = row.insertCell();
    const small = document.createElement('span'); small.className = 'small';
    small.textContent = scale.estimated ? ' depth reads × this' : ' given, not estimated';
    label.append('s', small);
    row.insertCell().textContent = scale.value.toFixed(4);
    const sigmaCell = row.insertCell();
    sigmaCell.textContent = scale.estimated && typeof scale.sigma === 'number' ? sig(scale.sigma) : '';
    if (predicted && typeof predicted.depth_scale === 'number') {
      const p = document.createElement('div'); p.className = 'small predicted';
      p.textContent = '(' + sig(predicted.depth_scale) + ')';
      sigmaCell.appendChild(p);
    }
    const activeScale = active && typeof active.depth_scale === 'number' ? active.depth_scale : null;
    const delta = activeScale === null ? null : scale.value - activeScale;
    row.insertCell().textContent = delta === null || Math.abs(delta) < 0.00005 ? '' : (delta > 0 ? '+' : '−') + Math.abs(delta).toFixed(4);
  }
}

// Each quality gate as it was checked, in words: what was measured (and
// where), against the limit, passed or not.
const GATE_WORDS = {
  theta_max_deg: ['ground angle θ, the worst pose', '°', 3],
  e_d_max_mm: ['ground height e_d, the worst pose', ' mm', 2],
  sigma_angle_max_deg: ['uncertainty of the angles, the worst', '°', 4],
  sigma_position_max_mm: ['uncertainty of the positions, the worst', ' mm', 3],
  min_poses_used: ['poses used', '', 0],
  min_used_fraction: ['share of the poses used', '%', 0],
  observable: ['how well the schedule pins the sensor down', '', 3],
  depth_scale_max_deviation: ['depth scale, off from 1 by', '%', 2],
};
function gateLines(result) {
  return (result.gate_checks || []).map((c) => {
    const [name, unit, digits] = GATE_WORDS[c.gate] || [c.gate, '', 3];
    const scale = unit === '%' ? 100 : 1;
    const value = (v) => (v * scale).toFixed(digits) + unit;
    const where = c.at ? ' (' + c.at + ')' : '';
    return (c.passed ? '✓ ' : '✗ ') + name + ': ' + value(c.measured) + where + ', ' + (c.at_least ? 'at least ' : 'at most ') + value(c.limit);
  });
}

// A check's figures in words: "ground tilt θ 0.003° (allowed 0.017°), …".
function checkFigures(report) {
  if (!report) return [];
  return report.checks.map((c) => {
    const unit = c.unit === 'deg' ? '°' : ' mm';
    const digits = c.unit === 'deg' ? 3 : 2;
    return c.name + ' ' + c.measured.toFixed(digits) + unit + ' (allowed ' + c.threshold.toFixed(digits) + unit + ')' + (c.passed ? '' : ' — too far');
  });
}

// ---- charts ----------------------------------------------------------------

const NS = 'http://www.w3.org/2000/svg';
function svgEl(parent, name, attributes, text) {
  const e = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attributes)) e.setAttribute(k, String(v));
  if (text !== undefined) e.textContent = text;
  parent.appendChild(e);
  return e;
}

// The scale: the smallest of a tenth, a quarter, a half or 1.25 × the gate
// that holds every used pose, so noise well under the gate looks small and
// a set-aside pose far above it does not flatten the rest (it is drawn at
// the top, with its value).
function scaleTop(values, gate) {
  const largest = Math.max(0, ...values);
  for (const f of [0.1, 0.25, 0.5, 1.25]) if (largest <= gate * f) return gate * f;
  return largest * 1.1;
}

// points: [{index, value, used}] over poses 1..count; gate: the limit.
function chart(svg, points, count, gate, unit) {
  while (svg.firstChild) svg.removeChild(svg.firstChild);
  const pts = points.filter((p) => typeof p.value === 'number');
  svg.dataset.points = String(pts.length);
  const left = 44; const right = 312; const top = 12; const bottom = 126;
  const yTop = scaleTop(pts.filter((p) => p.used).map((p) => p.value), gate);
  svg.dataset.top = String(yTop);
  const x = (i) => left + (count > 1 ? (i - 1) / (count - 1) : 0.5) * (right - left);
  const y = (v) => bottom - Math.min(v, yTop) / yTop * (bottom - top);
  const decimals = unit === '°' ? (yTop < 0.1 ? 3 : 2) : (yTop < 1 ? 2 : 1);
  for (const f of [0, 0.5, 1]) {
    const v = yTop * f;
    svgEl(svg, 'line', { x1: left, x2: right, y1: y(v), y2: y(v), stroke: '#ddd' });
    svgEl(svg, 'text', { x: left - 4, y: y(v) + 3, 'text-anchor': 'end' }, v.toFixed(decimals));
  }
  for (const i of [...new Set([1, Math.round((count + 1) / 2), count])]) {
    svgEl(svg, 'text', { x: x(i), y: bottom + 12, 'text-anchor': 'middle' }, String(i));
  }
  svgEl(svg, 'text', { x: right, y: bottom + 22, 'text-anchor': 'end' }, 'pose');
  svgEl(svg, 'line', { x1: left, x2: left, y1: top, y2: bottom, stroke: '#888' });
  svgEl(svg, 'line', { x1: left, x2: right, y1: bottom, y2: bottom, stroke: '#888' });
  if (gate <= yTop) {
    svgEl(svg, 'line', { class: 'gate', x1: left, x2: right, y1: y(gate), y2: y(gate), stroke: '#c62828', 'stroke-dasharray': '4 3' });
    svgEl(svg, 'text', { x: right - 2, y: y(gate) - 3, 'text-anchor': 'end', fill: '#c62828' }, 'gate ' + gate + unit);
  } else {
    svgEl(svg, 'text', { x: right - 2, y: top + 8, 'text-anchor': 'end', fill: '#c62828' }, 'gate ' + gate + unit + ' is above this scale');
  }
  const used = pts.filter((p) => p.used);
  if (used.length > 1) {
    svgEl(svg, 'polyline', { points: used.map((p) => x(p.index).toFixed(1) + ',' + y(p.value).toFixed(1)).join(' '), fill: 'none', stroke: '#1a6fd1', 'stroke-width': 1.2 });
  }
  for (const p of pts) {
    svgEl(svg, 'circle', { cx: x(p.index).toFixed(1), cy: y(p.value).toFixed(1), r: p.used ? 2 : 3.5, fill: p.used ? '#1a6fd1' : 'none', stroke: p.used ? 'none' : '#c62828', 'stroke-width': 1.5 });
    if (!p.used && p.value > yTop) {
      svgEl(svg, 'text', { x: x(p.index).toFixed(1), y: top + 2, 'text-anchor': 'middle', fill: '#c62828' }, '↑' + p.value.toFixed(unit === '°' ? 2 : 0));
    }
  }
}

// θ and e_d per pose: the result's, or while running the provisional solve's.
function charts(poses, count, provisional) {
  const gates = (model.status && model.status.gates) || { theta_max_deg: 1, e_d_max_mm: 5 };
  count = Math.max(count || 1, ...poses.map((p) => p.index));
  chart($('theta'), poses.map((p) => ({ index: p.index, value: p.theta_deg, used: p.used })), count, gates.theta_max_deg, '°');
  chart($('ed'), poses.map((p) => ({ index: p.index, value: p.e_d_mm, used: p.used })), count, gates.e_d_max_mm, ' mm');
  $('charts-title').textContent = provisional ? 'Fit per pose, so far' : 'Fit per pose';
  const fitted = poses.filter((p) => typeof p.theta_deg === 'number').length;
  // No empty charts: without a run or a result there is nothing to draw.
  $('charts').hidden = !provisional && !fitted;
  $('charts-note').textContent = provisional
    ? (fitted ? 'Each pose against the mount the poses so far give; it settles as poses arrive. Red rings: set aside.'
      : 'The charts start once six poses have a ground' + (model.status && model.status.pose ? ' (pose ' + model.status.pose + ' now).' : '.'))
    : (fitted ? 'Each pose against the result. Red rings: set aside.' : '');
  const aside = $('aside');
  aside.innerHTML = '';
  for (const p of poses.filter((q) => !q.used)) {
    const li = document.createElement('li');
    li.textContent = 'pose ' + p.index + ' set aside: ' + (p.reason || 'an outlier against the others');
    aside.appendChild(li);
  }
}

// ---- render ----------------------------------------------------------------

// Redraws a part of the page only when what it shows has changed: a button
// rebuilt every second would slip from under the operator's finger.
const drawn = new Map();
function redraw(id, key, draw) {
  if (drawn.get(id) === key) return;
  drawn.set(id, key);
  draw();
}

// How an aborted run left the robot, in words (the status's `robot_left`).
const LEFT = {
  home: 'at home',
  halted: 'halted, not at home',
  unknown: 'stopped: where the robot stands is not known',
  not_moved: 'stopped before moving',
};

function render() {
  const s = model.status;
  const lost = model.contact === 'lost';
  const running = !!s && s.state === 'running';
  const abort = s && s.abort;
  const aborting = running && !!abort && abort.state === 'aborting';
  const aborted = s && !running && abort && abort.state === 'aborted' ? abort : null;
  const activeId = s && s.active ? s.active.id : null;

  $('contact').textContent = model.contact === 'ok' ? 'connected' : (lost ? 'no contact' : 'connecting…');
  const banner = $('lost');
  banner.hidden = !lost;
  if (lost) {
    const seconds = Math.round((Date.now() - (model.heardAt || model.lostSince)) / 1000);
    banner.textContent = 'No contact with the robot\'s computer for ' + seconds + ' s: this page shows the last state it heard, which may be out of date.'
      + (running ? ' A run was going on: if groundcal has stopped, the robot\'s own watchdog halts the body within 1 s; if only this device\'s link is down, the run goes on.' : '')
      + ' Reconnecting…';
  }

  // What matters for safety stands out: a robot that may not have stopped,
  // or that did not reach home.
  const unsafe = aborted && (aborted.robot_left === 'unknown' || aborted.robot_left === 'halted') ? aborted.reason : null;
  $('safety').hidden = !unsafe;
  $('safety').textContent = unsafe ? (aborted.robot_left === 'unknown' ? 'The robot may not have stopped: ' : 'The robot halted but is not at home: ') + unsafe + '. Check it before anything else.' : '';

  // A sensor that moved since its calibration: the terrain map is wrong. The
  // check speaks only for the calibration it checked: after a new one is made
  // active, its banner goes.
  const ck = s && s.check && s.check.calibration_id === activeId ? s.check : null;
  const drift = ck && ck.outcome === 'drift';
  $('drift').hidden = !drift;
  $('drift-text').textContent = drift ? 'The sensor has moved since it was calibrated: '
    + ck.reasons.map((r) => r.replace(' than the active calibration says', '')).join('; ')
    + '. Meanwhile the robot still uses the active calibration (' + madeOn(activeId) + '), which no longer matches the sensor.' : '';
  redraw('drift-todo', drift ? 'drift' : '', () => list($('drift-todo'), drift ? [
    'Check that the sensor\'s mount is tight and that nothing has knocked it.',
    'Press Check again.',
    'If it still says the sensor has moved, press Calibrate, and Accept the new calibration when it passes its checks.',
  ] : []));

  // Progress.
  const checking = running && s.task === 'check';
  let title = 'connecting…';
  if (s) {
    if (running) title = aborting ? 'aborting…' : checking ? 'checking the sensor' : (s.pose ? 'pose ' + s.pose + ' of ' + s.of : 'starting');
    else title = aborted ? LEFT[aborted.robot_left] || 'stopped' : (s.result ? 'finished' : 'idle');
  }
  if (model.sending === 'Abort' && !aborting) title = 'sending Abort…';
  $('progress').textContent = title;
  $('bar').hidden = !running || aborting;
  if (running) $('bar-fill').style.width = (s.of ? 100 * Math.max(0, (s.pose || 1) - 1) / s.of : 0) + '%';
  // The step without the "pose i of N" the title already says.
  const step = ((s && s.step) || '').replace(/^pose \d+ of \d+: /, '');
  let stepText = step + (running && s.by ? ' — started by ' + s.by : '');
  if (!s || step === title) stepText = '';
  if (aborting) stepText = 'halting the robot and sending it home (Abort by ' + abort.by + ')';
  // Without contact the page knows only what it last heard, and no clock
  // runs on from it.
  if (lost && stepText) stepText = 'last heard: ' + stepText;
  $('step').textContent = stepText;
  if (running && !aborting && !lost && typeof s.elapsed_s === 'number') {
    const elapsed = s.elapsed_s + (Date.now() - model.statusAt) / 1000;
    $('times').textContent = duration(elapsed) + ' so far · '
      + (typeof s.remaining_s === 'number' ? 'about ' + duration(Math.max(0, s.remaining_s - (Date.now() - model.statusAt) / 1000)) + ' left' : 'time left: after the first pose');
  } else {
    $('times').textContent = '';
  }
  $('hardware').textContent = s && !running && s.hardware ? 'Hardware at the service\'s start: ' + s.hardware : '';
  $('calibrate').disabled = lost || !s || running || !!model.sending;
  $('check').disabled = lost || !s || running || !activeId || !!model.sending;
  // Abort stays pressable while the last known state is running, even with
  // no contact: pressing it then says that it could not be sent.
  $('abort').disabled = !running || aborting || model.sending === 'Abort';
  const plans = s && s.motion;
  const cr = model.confirmRun;
  $('confirm-run').hidden = !cr || running || lost;
  if (cr && plans) {
    const plan = plans[cr];
    $('confirm-run-text').textContent = (cr === 'calibration'
      ? 'Start a calibration? The robot will move its body through ' + plan.poses + ' poses for ' + about(plan.about_s) + '.'
      : 'Check the active calibration? The robot will walk to its home stance' + (plan.poses > 1 ? ' and tilt its body ' + (plan.poses - 1) + ' times' : '') + ', for ' + about(plan.about_s) + '.')
      + ' Keep everyone clear of the robot and its legs until it is back at home.';
    $('confirm-run-yes').textContent = cr === 'calibration' ? 'Yes, calibrate' : 'Yes, check';
  }
  // A message about the active calibration goes once another is active
  // (another device changed it).
  if (model.message && model.message.activeId && s && model.message.activeId !== activeId) model.message = null;
  const m = $('message');
  m.textContent = model.message ? model.message.text : '';
  m.className = model.message ? model.message.kind : '';

  // The result, or why there is none.
  const r = s && s.result;
  const card = $('result');
  const verdict = $('verdict');
  const reasons = $('reasons');
  reasons.innerHTML = '';
  const say = (text) => { const li = document.createElement('li'); li.textContent = text; reasons.appendChild(li); };
  let activeHere = false;
  if (s && r && (!running || checking)) {
    card.hidden = false;
    const passed = r.status === 'accepted';
    verdict.textContent = passed ? 'Passed its checks' : 'Failed its checks';
    verdict.className = passed ? 'passed' : 'failed';
    for (const reason of r.reasons || []) say(reason);
    const gates = gateLines(r);
    $('gates-box').hidden = !gates.length;
    $('gates-title').textContent = 'The checks: ' + gates.filter((g) => g.startsWith('✓')).length + ' of ' + gates.length + ' passed';
    redraw('gates', JSON.stringify([s.result_id, gates]), () => list($('gates'), gates));
    redraw('todo', passed ? '' : JSON.stringify([s.result_id, activeId]), () => list($('todo'), passed ? [] : todoFor(r)));
    $('todo-box').hidden = passed;
    const activeDoc = model.active && model.active.id === activeId ? model.active : null;
    const against = activeDoc && activeDoc.id !== s.result_id ? activeDoc : null;
    redraw('values', JSON.stringify([s.result_id, against && against.id]), () => {
      const scale = typeof r.depth_scale === 'number'
        ? { value: r.depth_scale, sigma: r.sigma && r.sigma.depth_scale, estimated: !!r.depth_scale_estimated } : null;
      if (r.robot_from_sensor) valuesTable($('values'), r.robot_from_sensor, r.sigma, against, r.predicted_sigma, scale);
      else $('values').innerHTML = '';
    });
    activeHere = !!activeId && activeId === s.result_id;
    $('change').textContent = r.robot_from_sensor && !activeHere ? changeInWords(r.robot_from_sensor, activeDoc) : '';
    $('activeline').innerHTML = '';
    if (activeHere) {
      const badge = document.createElement('span'); badge.className = 'active-badge'; badge.textContent = 'Active';
      $('activeline').append(badge, ' since ' + when(s.active.activated));
    } else {
      $('activeline').textContent = passed ? 'Not active yet: Accept makes it the calibration the robot uses.' : 'It failed its checks, so it cannot become active.';
    }
    $('resultid').textContent = s.result_id ? 'calibration of ' + madeOn(s.result_id) : '';
    $('resultid').dataset.id = s.result_id || '';
    $('resultid').title = s.result_id || '';
    redraw('charts', 'result ' + s.result_id, () => charts(r.poses || [], s.of, false));
  } else if (s && !running && (s.interrupted || (s.error && !aborted))) {
    card.hidden = false;
    const cut = s.interrupted;
    $('todo-box').hidden = true;
    $('gates-box').hidden = true;
    verdict.textContent = cut ? 'Interrupted' : 'No result';
    verdict.className = cut ? 'interrupted' : 'failed';
    if (cut) {
      say('The calibration started by ' + cut.by + ' on ' + when(cut.started) + ' was cut off: the service stopped before it finished.');
      say('The robot\'s own watchdog halts the body within 1 s once groundcal falls silent, so it stands where the run was cut off. Check that it stands safely and that nobody is near it.');
      say(s.startup_check === 'held_for_a_person'
        ? 'Nothing moves until someone asks: the check at start was held. Press Check (the robot walks home first) or Calibrate when the robot is clear.'
        : 'Nothing moves until someone presses Calibrate or Check.');
    } else {
      say(s.error);
    }
    redraw('values', 'none', () => { $('values').innerHTML = ''; });
    $('change').textContent = ''; $('activeline').textContent = ''; $('resultid').textContent = '';
    redraw('charts', 'none', () => charts([], 1, false));
  } else {
    card.hidden = true;
    if (running && !checking) redraw('charts', JSON.stringify(['running', s.provisional, s.of, s.pose]), () => charts(s.provisional || [], s.of || 1, true));
    else redraw('charts', 'none', () => charts([], 1, false));
  }
  $('accept').hidden = activeHere || !(r && r.status === 'accepted');
  $('accept').disabled = lost || running || !r || r.status !== 'accepted' || !s.result_id || activeHere;

  const c = model.confirm;
  $('confirm').hidden = !c;
  if (c) {
    $('confirm-text').textContent = (c.kind === 'accept' ? 'Make the calibration of ' + madeOn(c.id) + ' the active one?' : 'Roll back to the calibration of ' + madeOn(c.id) + '?')
      + ' The robot\'s other programs use the active calibration from their next start.';
    $('confirm').scrollIntoView({ block: 'nearest' });
  }
  $('confirm-yes').disabled = lost;

  // The active calibration and the history. The status names the active one
  // (every device the same); its document is loaded when that changes.
  const a = model.active && model.active.id === activeId ? model.active : null;
  $('active').textContent = activeId ? 'The calibration of ' + madeOn(activeId) + ', active since ' + when(s.active.activated) : 'None yet: the robot uses no calibration from groundcal.';
  $('active').dataset.id = activeId || '';
  $('active').title = activeId || '';
  const line = $('checkline');
  line.className = ck ? ck.outcome : '';
  if (!ck) line.textContent = a ? 'Not checked since it became active or since the service started: Check compares it with the sensor now.' : '';
  else if (ck.outcome === 'running') line.textContent = 'Checking it against the sensor now…';
  else if (ck.outcome === 'failed') line.textContent = 'The last check (' + when(ck.started) + ') could not be made: ' + (ck.error || 'no reason given');
  else line.textContent = 'Checked ' + when(ck.finished) + (ck.by ? ' (' + ck.by + ')' : '') + ': '
    + (drift ? 'the sensor has moved since it was calibrated.' : 'the sensor agrees with it.');
  redraw('checks', JSON.stringify(ck && ck.report ? [ck.finished, ck.report.checks] : null), () => {
    const report = ck && ck.report;
    const unseen = report && report.not_checked.length ? ['not seen from where it stood: ' + report.not_checked.join(', ')] : [];
    list($('checks'), checkFigures(report).concat(unseen));
  });
  redraw('history', JSON.stringify([model.history.slice(0, 20), activeId, lost || running]), () => {
    const history = $('history');
    history.innerHTML = '';
    if (!model.history.length) history.insertRow().insertCell().textContent = 'No calibrations yet.';
    for (const h of model.history.slice(0, 20)) {
      const row = history.insertRow();
      row.insertCell().textContent = when(h.created);
      row.insertCell().textContent = h.operator_rejected ? 'set aside by an operator' : h.status === 'accepted' ? 'passed its checks' : h.status === 'rejected' ? 'failed its checks' : h.status;
      const cell = row.insertCell();
      if (h.id === activeId) {
        const badge = document.createElement('span'); badge.className = 'active-badge'; badge.textContent = 'Active'; cell.appendChild(badge);
      } else if (h.status === 'accepted') {
        const b = document.createElement('button');
        b.className = 'small rollback'; b.textContent = a ? 'Roll back to this' : 'Make active';
        b.dataset.id = h.id; b.disabled = lost || running;
        b.onclick = () => { model.confirm = { kind: 'rollback', id: h.id }; render(); };
        cell.appendChild(b);
      }
      row.title = h.id;
    }
  });
}

// ---- contact with the daemon ----------------------------------------------

// A page that cannot reach the daemon must not look alive. The daemon is
// heard from through the heartbeat of its event stream (every second), its
// events and the status polls (every second, each given up after 2 s);
// contact is lost when it has said nothing for SILENCE_MS, or at once when a
// request fails outright (a refused connection). A stopped daemon, or a
// link that dropped without closing, is therefore declared lost within
// about 2 s. A closed event stream (the daemon closes the oldest under a
// flood of streams) is opened again after a back-off from 1 s to 5 s, while
// the status polls go on.
function heard() {
  const wasLost = model.contact !== 'ok';
  model.heardAt = Date.now();
  model.contact = 'ok';
  model.lostSince = null;
  if (wasLost) { loadStore(); render(); }
}
function lose() {
  if (model.contact !== 'lost') { model.contact = 'lost'; model.lostSince = Date.now(); }
  render();
}
let retry = 1000;
async function refresh() {
  try {
    const r = await fetchWithin('/api/status', {}, 2000);
    if (!r.ok) { lose(); return false; }
    const s = await r.json();
    const activeBefore = model.status && model.status.active ? model.status.active.id : null;
    model.status = s;
    model.statusAt = Date.now();
    heard();
    retry = 1000;
    // Another device accepted or rolled back: the store is read again.
    const activeNow = s.active ? s.active.id : null;
    if (activeNow !== activeBefore || (activeNow && (!model.active || model.active.id !== activeNow))) loadStore();
    render();
    return true;
  } catch (e) { lose(); return false; }
}
// The history, and the active calibration's document (GET /api/active
// answers 404 when none is).
let loading = null;
function loadStore() {
  if (loading) return loading;
  loading = (async () => {
    try {
      const history = await fetchWithin('/api/calibrations');
      model.history = history.ok ? (await history.json()).calibrations || [] : [];
      let active = null;
      if (model.status && model.status.active) {
        const r = await fetchWithin('/api/active');
        active = r.ok ? await r.json() : null;
      }
      model.active = active;
      render();
    } catch (e) { lose(); } finally { loading = null; }
  })();
  return loading;
}

let events = null;
function listen() {
  events = new EventSource('/api/events');
  events.onopen = () => { retry = 1000; refresh(); };
  events.onerror = () => {
    // EventSource retries by itself, but not after some failures: start over
    // with a back-off. The status poll says whether the daemon is there.
    events.close();
    refresh();
    setTimeout(listen, retry);
    retry = Math.min(retry * 2, 5000);
  };
  events.onmessage = (m) => {
    let e; try { e = JSON.parse(m.data); } catch (x) { return; }
    heard();
    if (e.type === 'heartbeat') return;
    if (e.type === 'provisional' && model.status) {
      model.status.provisional = e.poses;
      render();
    } else {
      if (e.type === 'stored' || e.type === 'failed' || e.type === 'checked' || e.type === 'activated') loadStore();
      refresh();
    }
  };
}

listen();
refresh();
setInterval(() => { refresh(); }, 1000);
// Silence: no heartbeat, no event and no status for SILENCE_MS.
setInterval(() => {
  if (model.contact === 'ok' && Date.now() - model.heardAt > SILENCE_MS) lose();
  else if (model.contact === 'lost') render();
}, 200);
