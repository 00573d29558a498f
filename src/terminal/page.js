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

// ---- the language ----------------------------------------------------------

// The browser's language unless the operator chose one on this device; the
// words come from WORDS (page-words.js).
function chooseLanguage() {
  const saved = localStorage.getItem('groundcal-language');
  if (saved && WORDS[saved]) return saved;
  for (const l of navigator.languages || [navigator.language || 'en']) {
    const base = String(l).toLowerCase().split('-')[0];
    if (WORDS[base]) return base;
  }
  return 'en';
}
let language = chooseLanguage();
// A word of the catalogue; a function word is called with `args`.
function t(key, ...args) {
  const w = key in WORDS[language] ? WORDS[language][key] : WORDS.en[key];
  return typeof w === 'function' ? w(...args) : w;
}
// The page's fixed words: elements marked data-w (text), data-w-title and
// data-w-placeholder.
function applyLanguage() {
  document.documentElement.lang = language === 'zh' ? 'zh-CN' : 'en';
  for (const e of document.querySelectorAll('[data-w]')) e.textContent = t(e.dataset.w);
  for (const e of document.querySelectorAll('[data-w-title]')) e.title = t(e.dataset.wTitle);
  for (const e of document.querySelectorAll('[data-w-placeholder]')) e.placeholder = t(e.dataset.wPlaceholder);
  const select = $('language');
  select.innerHTML = '';
  for (const [code, words] of Object.entries(WORDS)) {
    const option = document.createElement('option');
    option.value = code; option.textContent = words.languageName; option.selected = code === language;
    select.appendChild(option);
  }
  drawn.clear();
}
// Text that came from the robot's computer as English words, marked so.
function english(element, text) {
  element.textContent = text;
  element.lang = 'en';
}

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
  starting: null, // 'calibration' | 'check': confirmed, until the daemon says it runs
  message: null, // {text, kind: 'error' | 'ok'}
  abortNote: null, // {text, kind: 'error' | 'pending' | 'ok'}: what became of Abort
  // An Abort that could not be sent: {started, at} of the run it stops. It
  // is kept in this device's storage (a reload keeps it) and sent the
  // moment the daemon answers again.
  pendingAbort: null,
  statusAt: 0, // when the status was read (for the time so far)
};

// Contact is lost when the daemon has said nothing for this long: two
// heartbeats of its event stream (one a second) missed, and the status polls
// (one a second) unanswered. A request gives up after REQUEST_MS.
const SILENCE_MS = 2200;
const REQUEST_MS = 3000;

// The six values: key and unit (their names are words of the catalogue).
const PARAMS = [
  ['alpha_deg', '°'],
  ['beta_deg', '°'],
  ['gamma_deg', '°'],
  ['px_mm', ' mm'],
  ['py_mm', ' mm'],
  ['pz_mm', ' mm'],
];
const paramName = (key) => t('params')[key][0];
const paramWords = (key) => t('params')[key][1];

// ---- the token and the calls that need it --------------------------------

const tokenField = $('token');
tokenField.value = localStorage.getItem('groundcal-token') || '';
$('token-card').open = !tokenField.value;
tokenField.addEventListener('input', () => localStorage.setItem('groundcal-token', tokenField.value.trim()));
// A token typed now makes the live stream the operator's: it is opened again.
tokenField.addEventListener('change', () => { if (events) { events.close(); listen(); } });

// What an error answer means for an operator.
function explain(response, body) {
  const token = tokenField.value.trim();
  if (response.status === 401) {
    $('token-card').open = true;
    return token ? t('tokenWrong') : t('tokenFirst');
  }
  if (response.status === 403 || response.status === 421) {
    return t('refused');
  }
  return (body && body.error) || t('answered', response.status);
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
  return t('notSent', what, timedOut, running, REQUEST_MS / 1000);
}

// `what` names the button in the words shown when it fails ("Abort").
async function call(method, url, what) {
  const headers = { 'Authorization': 'Bearer ' + tokenField.value.trim(), 'X-Groundcal-Client': encodeURIComponent(t('clientName')) };
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
// long and to keep clear. Cancel sends nothing. Without a token nothing can
// start, so that is said first, before any question.
function askToRun(kind) {
  model.confirm = null;
  if (!tokenField.value.trim()) {
    model.confirmRun = null;
    model.message = { text: t('tokenFirst'), kind: 'error' };
    $('token-card').open = true;
    tokenField.focus();
  } else {
    model.message = null;
    model.confirmRun = kind;
  }
  render();
}
$('calibrate').onclick = () => askToRun('calibration');
// A check of the active calibration against the sensor now (the robot holds
// its home stance, or tilts a little with [verify] poses).
$('check').onclick = () => askToRun('check');
$('confirm-run-no').onclick = () => { model.confirmRun = null; render(); };
$('confirm-run-yes').onclick = async () => {
  const kind = model.confirmRun;
  model.confirmRun = null;
  if (!kind) return;
  // Until the daemon says it runs, the page says it is starting (not the
  // last run's outcome).
  model.starting = kind;
  model.abortNote = null;
  const started = kind === 'calibration'
    ? await call('POST', '/api/calibrations', t('calibrate'))
    : await call('POST', '/api/check', t('check'));
  if (started) await refresh();
  model.starting = null;
  render();
};

// ---- Abort ---------------------------------------------------------------

// Abort is never pretended: the page says "aborting…" only once the daemon
// has it (the status's `abort`). An Abort that could not be sent is not
// forgotten: it is kept (in this device's storage, so a reload keeps it) and
// sent the moment the daemon answers again, for the run it was pressed for.
// Another device cannot know of it; the note says so.
const PENDING_ABORT = 'groundcal-pending-abort';
function keepPendingAbort(started) {
  model.pendingAbort = { started, at: Date.now(), kept: true };
  try { localStorage.setItem(PENDING_ABORT, JSON.stringify({ started, at: model.pendingAbort.at })); } catch (e) { model.pendingAbort.kept = false; }
}
function dropPendingAbort() {
  model.pendingAbort = null;
  try { localStorage.removeItem(PENDING_ABORT); } catch (e) { /* nothing kept */ }
}
try {
  const kept = JSON.parse(localStorage.getItem(PENDING_ABORT) || 'null');
  // An Abort older than a day stops nothing a person still waits on.
  if (kept && Date.now() - kept.at < 86_400_000) model.pendingAbort = { started: kept.started, at: kept.at, kept: true };
  else dropPendingAbort();
} catch (e) { dropPendingAbort(); }

async function sendAbort() {
  model.confirmRun = null;
  const s = model.status;
  const started = (model.pendingAbort && model.pendingAbort.started) || (s && s.started) || null;
  const headers = { 'Authorization': 'Bearer ' + tokenField.value.trim(), 'X-Groundcal-Client': encodeURIComponent(t('clientName')) };
  // With no contact it is pending from the moment it is pressed: the
  // request may take its whole time to fail.
  if (model.contact === 'lost' && !model.pendingAbort) keepPendingAbort(started);
  model.sending = t('abort');
  render();
  let response;
  let body = {};
  try {
    response = await fetchWithin('/api/calibrations/current/abort', { method: 'POST', headers });
    try { body = await response.json(); } catch (e) { body = {}; }
  } catch (e) {
    model.sending = null;
    keepPendingAbort(started);
    model.abortNote = { text: t('abortPending', e && e.name === 'AbortError', REQUEST_MS / 1000, model.pendingAbort.kept), kind: 'pending' };
    lose();
    return;
  }
  model.sending = null;
  heard();
  if (response.ok) {
    dropPendingAbort();
    model.abortNote = null;
  } else if (response.status === 409) {
    // Nothing runs any more: the run ended before the Abort reached it (the
    // status says how: the daemon aborts by itself a run it stalled in).
    dropPendingAbort();
    model.abortNote = { text: t('abortNothingRunning'), kind: 'ok' };
  } else {
    model.abortNote = { text: explain(response, body), kind: 'error' };
  }
  await refresh();
}
$('abort').onclick = sendAbort;

// Contact is back: a pending Abort goes at once, if its run still runs.
async function flushPendingAbort() {
  const p = model.pendingAbort;
  if (!p || model.sending) return;
  const s = model.status;
  if (s && s.state === 'running' && (!p.started || s.started === p.started)) {
    await sendAbort();
  } else if (s) {
    dropPendingAbort();
    model.abortNote = { text: t('abortNothingRunning'), kind: 'ok' };
    render();
  }
}
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
  const active = await call('POST', url, c.kind === 'accept' ? t('accept') : t('rollBack'));
  if (active) {
    model.active = active;
    const wasActive = model.status && model.status.active;
    model.message = { text: t(c.kind === 'accept' ? 'accepted' : wasActive ? 'rolledBack' : 'madeActive', madeOn(c.id)), kind: 'ok', activeId: c.id };
    loadStore();
  }
  render();
};

// ---- words and numbers ---------------------------------------------------

function duration(seconds) {
  const s = Math.max(0, Math.round(seconds));
  if (s < 60) return t('seconds', s);
  return t('minutesSeconds', Math.floor(s / 60), s % 60);
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
  theta_max_deg: 'todoGround',
  e_d_max_mm: 'todoFeet',
  sigma_angle_max_deg: 'todoStill',
  sigma_position_max_mm: 'todoStill',
  min_poses_used: 'todoNoGround',
  min_used_fraction: 'todoNoGround',
  depth_scale_max_deviation: 'todoScale',
  depth_scale_taken_sigmas: 'todoScaleTaken',
  warp_max_mm: 'todoWarp',
  pattern_max_mm: 'todoPattern',
  pattern_angle_sigma_growth_max: 'todoPatternSchedule',
  observable: 'todoSchedule',
};
function todoFor(result) {
  const lines = [];
  // A depth scale the poses rule out fails the heights' gate by itself:
  // flat ground and another run would not help (its own line says so).
  const scaleTaken = (result.gate_checks || []).some((c) => c.gate === 'depth_scale_taken_sigmas' && !c.passed);
  for (const c of result.gate_checks || []) {
    if (scaleTaken && c.gate === 'e_d_max_mm') continue;
    // A pattern fixed in the image that the paper's fit left uncorrected
    // needs the default fit, not flat ground.
    const fixedWarp = c.gate === 'warp_max_mm' && result.depth_pattern && result.depth_pattern.uncorrected_fixed;
    // Far poses that disagree by the sensor's own noise: the ground is
    // flat already, and calibrating again would not help; a σ too large
    // beside it comes from the same noise ("press Calibrate again" was
    // shown next to "do not calibrate again").
    const farNoise = result.e_d_from_sensor_noise
      && ['e_d_max_mm', 'sigma_angle_max_deg', 'sigma_position_max_mm'].includes(c.gate);
    const todo = fixedWarp ? 'todoWarpFixed' : farNoise ? 'todoFarNoise' : TODO[c.gate];
    const line = !c.passed && TODO[c.gate] && t(todo);
    if (line && !lines.includes(line)) lines.push(line);
  }
  if ((result.reasons || []).some((r) => /motor/.test(r))) lines.push(t('todoMotor'));
  if (!lines.length) lines.push(t('todoAgain'));
  const active = model.status && model.status.active;
  lines.push(active ? t('meanwhileActive', madeOn(active.id)) : t('meanwhileNone'));
  return lines;
}

// "about 2 min", "about 10 s": how long the robot will move.
function about(seconds) {
  return seconds >= 90 ? t('aboutMinutes', Math.round(seconds / 60)) : t('aboutSeconds', Math.max(1, Math.round(seconds)));
}
// A time in the device's own time zone, in the page's language.
function when(rfc3339) {
  const time = new Date(rfc3339);
  // In English, the device's English (en-GB, en-US…) if it has one, else
  // plain English: never a date in another language beside English words.
  const english = (navigator.languages || []).find((l) => /^en\b/i.test(l)) || 'en';
  const locale = language === 'zh' ? 'zh-CN' : english;
  return isNaN(time) ? (rfc3339 || '?') : time.toLocaleString(locale, { dateStyle: 'medium', timeStyle: 'medium' });
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
  for (const [key, unit] of PARAMS) {
    const delta = mount[key] - active.robot_from_sensor[key];
    const slot = { name: paramName(key), delta, unit };
    if (unit === '°') { if (!angle || Math.abs(delta) > Math.abs(angle.delta)) angle = slot; } else if (!shift || Math.abs(delta) > Math.abs(shift.delta)) shift = slot;
  }
  return t('changeAgainst', madeOn(active.id), Math.abs(angle.delta).toFixed(3), angle.name, Math.abs(shift.delta).toFixed(1), shift.name);
}

// predicted: the σ `plan` predicted before the robot moved (shown under
// the achieved σ, to compare).
// scale: the result's depth scale ({value, sigma, estimated}), a row of its own.
function valuesTable(table, mount, sigma, active, predicted, scale) {
  table.innerHTML = '';
  const head = table.insertRow();
  // Short headers, the longer words small beneath: at phone width every
  // column must fit.
  for (const [h, under] of [['', ''], [t('colValue'), ''], ['±σ', predicted ? t('colPredicted') : ''], [active ? t('colChange') : '', '']]) {
    const th = document.createElement('th'); th.textContent = h;
    if (under) { const small = document.createElement('div'); small.className = 'small'; small.textContent = under; th.appendChild(small); }
    head.appendChild(th);
  }
  for (const [key, unit] of PARAMS) {
    const row = table.insertRow();
    const label = row.insertCell();
    const small = document.createElement('span'); small.className = 'small'; small.textContent = ' ' + paramWords(key);
    label.append(paramName(key), small);
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
    small.textContent = scale.estimated ? t('scaleEstimated') : t('scaleGiven');
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
// Each gate's unit and digits (its name is a word of the catalogue).
const GATE_UNITS = {
  theta_max_deg: ['°', 3],
  e_d_max_mm: [' mm', 2],
  sigma_angle_max_deg: ['°', 4],
  sigma_position_max_mm: [' mm', 3],
  min_poses_used: ['', 0],
  min_used_fraction: ['%', 0],
  observable: ['', 3],
  depth_scale_max_deviation: ['%', 2],
  depth_scale_taken_sigmas: [' σ', 1],
  warp_max_mm: [' mm', 1],
  pattern_max_mm: [' mm', 1],
  pattern_angle_sigma_growth_max: ['×', 1],
};
// Where a gate's value comes from (the check's typed `place`), in words.
const AXES = ['forward', 'up', 'right'];
function placeInWords(place) {
  if (!place) return '';
  let words = '';
  if (place.kind === 'pose') words = t('poseN', place.index);
  else if (place.kind === 'parameter') { const key = PARAMS[place.index][0]; words = paramName(key) + ', ' + paramWords(key); }
  else if (place.kind === 'poses_used') words = t('posesUsedOf', place.used, place.total);
  else if (place.kind === 'direction') {
    const a = place.axis.map(Math.abs);
    const k = a.indexOf(Math.max(...a));
    words = t(place.rotation ? 'weakRotation' : 'weakPosition', t('axes')[AXES[k]]);
  }
  return words ? ' (' + words + ')' : '';
}
function gateLines(result) {
  return (result.gate_checks || []).map((c) => {
    const [unit, digits] = GATE_UNITS[c.gate] || ['', 3];
    const name = t('gates')[c.gate] || c.gate;
    const scale = unit === '%' ? 100 : 1;
    const value = (v) => (v * scale).toFixed(digits) + unit;
    const where = placeInWords(c.place);
    return (c.passed ? '✓ ' : '✗ ') + name + ': ' + value(c.measured) + where + ', ' + (c.at_least ? t('atLeast') : t('atMost')) + value(c.limit);
  });
}

// Why a check says the sensor moved: in English the daemon's own words;
// in another language from the typed drifts ("the ground says the sensor is
// pitched 0.30° more down"), each direction with its sign.
function driftInWords(check) {
  const report = check.report;
  if (language === 'en' || !report || !report.drifts || !report.drifts.length) {
    return check.reasons.map((r) => r.replace(' than the active calibration says', '')).join('; ');
  }
  return report.drifts.map((d) => {
    const changes = d.changes.map((c) => t('driftChange', c.direction, Math.abs(c.change).toFixed(c.unit === 'deg' ? 2 : 1), c.change >= 0));
    return t(d.from === 'gravity' ? (d.ground_disagrees ? 'gravitySaysNotGround' : 'gravitySays') : 'groundSays', changes.join(t('andJoin')));
  }).join(t('sentenceJoin'));
}

// A check's figures in words: "ground tilt θ 0.003° (allowed 0.017°), …".
function checkFigures(report) {
  if (!report) return [];
  return report.checks.map((c) => {
    const unit = c.unit === 'deg' ? '°' : ' mm';
    const digits = c.unit === 'deg' ? 3 : 2;
    return t('checkFigure', t('checkNames')[c.name] || c.name, c.measured.toFixed(digits) + unit, c.threshold.toFixed(digits) + unit, c.passed);
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
  svgEl(svg, 'text', { x: right, y: bottom + 22, 'text-anchor': 'end' }, t('pose'));
  svgEl(svg, 'line', { x1: left, x2: left, y1: top, y2: bottom, stroke: '#888' });
  svgEl(svg, 'line', { x1: left, x2: right, y1: bottom, y2: bottom, stroke: '#888' });
  if (gate <= yTop) {
    svgEl(svg, 'line', { class: 'gate', x1: left, x2: right, y1: y(gate), y2: y(gate), stroke: '#c62828', 'stroke-dasharray': '4 3' });
    svgEl(svg, 'text', { x: right - 2, y: y(gate) - 3, 'text-anchor': 'end', fill: '#c62828' }, t('gate', gate + unit));
  } else {
    svgEl(svg, 'text', { x: right - 2, y: top + 8, 'text-anchor': 'end', fill: '#c62828' }, t('gateAbove', gate + unit));
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
  $('charts-title').textContent = provisional ? t('fitPerPoseSoFar') : t('fitPerPose');
  const fitted = poses.filter((p) => typeof p.theta_deg === 'number').length;
  // No empty charts: without a run or a result there is nothing to draw.
  $('charts').hidden = !provisional && !fitted;
  $('charts-note').textContent = provisional
    ? (fitted ? t('chartsSoFar') : t('chartsWaiting', model.status && model.status.pose))
    : (fitted ? t('chartsResult') : '');
  const aside = $('aside');
  aside.innerHTML = '';
  for (const p of poses.filter((q) => !q.used)) {
    const li = document.createElement('li');
    li.textContent = t('setAside', p.index, p.reason || t('anOutlier'));
    if (p.reason) li.lang = 'en';
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

// The commanded body pose in words: "rolled 20° right, body at 615 mm".
function bodyPoseInWords(p) {
  const n = (v) => String(Math.round(Math.abs(v) * 10) / 10);
  const parts = [];
  if (Math.abs(p.gamma_deg) >= 0.05) parts.push(t('rolled', n(p.gamma_deg), p.gamma_deg > 0));
  if (Math.abs(p.beta_deg) >= 0.05) parts.push(t('pitched', n(p.beta_deg), p.beta_deg > 0));
  if (Math.abs(p.alpha_deg) >= 0.05) parts.push(t('turned', n(p.alpha_deg), p.alpha_deg > 0));
  if (Math.abs(p.px_mm) >= 0.05) parts.push(t('shiftedForward', n(p.px_mm), p.px_mm > 0));
  if (Math.abs(p.pz_mm) >= 0.05) parts.push(t('shiftedSide', n(p.pz_mm), p.pz_mm > 0));
  parts.push(t('bodyAt', String(Math.round(p.py_mm * 10) / 10)));
  return parts.join(t('listJoin'));
}

// What the session does now, from the status's typed phase.
function phaseInWords(s) {
  if (!s.phase) return s.state === 'running' ? t('opening') : '';
  const words = t('phases')[s.phase] || s.phase;
  if (s.phase === 'moving' && s.commanded) return words + ' (' + bodyPoseInWords(s.commanded) + ')';
  return words;
}

function render() {
  renderView();
  const s = model.status;
  const lost = model.contact === 'lost';
  const running = !!s && s.state === 'running';
  const abort = s && s.abort;
  const aborting = running && !!abort && abort.state === 'aborting';
  const aborted = s && !running && abort && abort.state === 'aborted' ? abort : null;
  const activeId = s && s.active ? s.active.id : null;

  $('contact').textContent = model.contact === 'ok' ? t('connected') : (lost ? t('noContact') : t('connecting'));
  const banner = $('lost');
  banner.hidden = !lost;
  if (lost) {
    const seconds = Math.round((Date.now() - (model.heardAt || model.lostSince)) / 1000);
    banner.textContent = t('lostBanner', seconds, running);
  }

  // What matters for safety stands out: a robot that may not have stopped,
  // or that did not reach home.
  const unsafe = aborted && (aborted.robot_left === 'unknown' || aborted.robot_left === 'halted') ? aborted.reason : null;
  $('safety').hidden = !unsafe;
  $('safety').textContent = unsafe ? t(aborted.robot_left === 'unknown' ? 'mayNotHaveStopped' : 'notAtHome', unsafe) : '';

  // A sensor that moved since its calibration: the terrain map is wrong. The
  // banner stands on the last check that reached a verdict (kept by the
  // daemon across any stop; a check that could not be made does not clear
  // it), and speaks only for the calibration it checked: after a new one is
  // made active, it goes.
  const ck = s && s.check && s.check.calibration_id === activeId ? s.check : null;
  const lastVerdict = s && s.verdict && s.verdict.calibration_id === activeId ? s.verdict : null;
  const drift = !!lastVerdict && lastVerdict.outcome === 'drift';
  $('drift').hidden = !drift;
  $('drift-text').textContent = drift ? t('driftText', madeOn(activeId), driftInWords(lastVerdict)) : '';
  redraw('drift-todo', drift ? 'drift ' + language : '', () => list($('drift-todo'), drift ? t('driftTodo') : []));

  // Progress.
  const checking = running && s.task === 'check';
  let title = t('connecting');
  if (s) {
    if (running) title = aborting ? t('aborting') : checking ? t('checkingSensor') : (s.pose ? t('poseOf', s.pose, s.of) : t('starting'));
    else if (model.starting) title = t('starting');
    else title = aborted ? t('abortedTitle', t('left')[aborted.robot_left] || t('stopped')) : (s.result ? t('finished') : t('idle'));
  }
  if (model.sending === t('abort') && !aborting) title = t('sendingAbort');
  if (model.pendingAbort && !aborting) title = t('abortPendingTitle');
  $('progress').textContent = title;
  $('bar').hidden = !running || aborting;
  if (running) $('bar-fill').style.width = (s.of ? 100 * Math.max(0, (s.pose || 1) - 1) / s.of : 0) + '%';
  // The step (the title already says which pose), and what its event said
  // in words of its own: in English after the step, in another language
  // on a line of its own, marked as English.
  let step = s ? phaseInWords(s) : '';
  const detail = s && s.detail && !lost ? s.detail : '';
  if (detail && language === 'en') step += ': ' + detail;
  $('step-detail').hidden = !detail || language === 'en';
  $('step-detail').textContent = detail ? detail + t('inEnglish') : '';
  let stepText = step + (running && s.by ? t('startedBy', s.by) : '');
  if (!s || step === title || !step) stepText = '';
  if (aborting) stepText = t('haltingForAbort', abort.by);
  // Without contact the page knows only what it last heard, and no clock
  // runs on from it.
  if (lost && stepText) stepText = t('lastHeard', stepText);
  $('step').textContent = stepText;
  if (running && !aborting && !lost && typeof s.elapsed_s === 'number') {
    const elapsed = s.elapsed_s + (Date.now() - model.statusAt) / 1000;
    $('times').textContent = t('soFar', duration(elapsed)) + ' · '
      + (typeof s.remaining_s === 'number' ? t('left_', duration(Math.max(0, s.remaining_s - (Date.now() - model.statusAt) / 1000))) : t('afterFirstPose'));
  } else {
    $('times').textContent = '';
  }
  // The hardware as the service found it at start: its words are the
  // daemon's, in English, marked so.
  const hardware = $('hardware');
  hardware.textContent = '';
  if (s && !running && s.hardware) {
    const words = document.createElement('span');
    english(words, s.hardware + t('inEnglish'));
    hardware.append(t('hardwareAtStart'), words);
  }
  $('calibrate').disabled = lost || !s || running || !!model.sending || !!model.starting;
  $('check').disabled = lost || !s || running || !activeId || !!model.sending || !!model.starting;
  // Abort stays pressable while the last known state is running, even with
  // no contact (pressing it then keeps it pending), and while one is pending.
  const pending = model.pendingAbort;
  $('abort').disabled = !(running || pending) || aborting || model.sending === t('abort');
  // Docked at the foot of the screen while it matters, with its outcome.
  const docked = running || !!pending;
  $('abort-dock').classList.toggle('docked', docked);
  document.body.classList.toggle('docked', docked);
  const note = $('abort-note');
  const noteWords = pending && !(model.abortNote && model.abortNote.kind === 'pending')
    ? { text: t('abortPending', false, REQUEST_MS / 1000, pending.kept), kind: 'pending' }
    : model.abortNote;
  note.textContent = noteWords ? noteWords.text : '';
  note.className = noteWords ? noteWords.kind : '';
  const plans = s && s.motion;
  const cr = model.confirmRun;
  $('confirm-run').hidden = !cr || running || lost;
  if (cr && plans) {
    const plan = plans[cr];
    // How long: as the last run of its kind took here, else the robot's
    // nominal time (a faster simulator is not the robot).
    const howLong = typeof plan.last_s === 'number' ? t('asLastTook', about(plan.last_s))
      : t(plan.simulated ? 'atSimulatorSpeed' : 'atNominalSpeed', about(plan.about_s));
    $('confirm-run-text').textContent = (cr === 'calibration'
      ? t('confirmCalibrate', plan.poses, howLong)
      : t('confirmCheck', plan.poses > 1 ? plan.poses - 1 : 0, howLong))
      + t('keepClear');
    $('confirm-run-yes').textContent = cr === 'calibration' ? t('yesCalibrate') : t('yesCheck');
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
  // `fromRobot`: English words that came from the robot's computer.
  const say = (text, fromRobot) => {
    const li = document.createElement('li');
    if (fromRobot) english(li, text + t('inEnglish')); else li.textContent = text;
    reasons.appendChild(li);
  };
  let activeHere = false;
  if (s && r && (!running || checking)) {
    card.hidden = false;
    const passed = r.status === 'accepted';
    verdict.textContent = passed ? t('passedChecks') : t('failedChecks');
    verdict.className = passed ? 'passed' : 'failed';
    for (const reason of r.reasons || []) say(reason, true);
    const gates = gateLines(r);
    $('gates-box').hidden = !gates.length;
    $('gates-title').textContent = t('checksPassed', gates.filter((g) => g.startsWith('✓')).length, gates.length);
    redraw('gates', JSON.stringify([s.result_id, gates]), () => list($('gates'), gates));
    redraw('todo', passed ? '' : JSON.stringify([s.result_id, activeId, language]), () => list($('todo'), passed ? [] : todoFor(r)));
    $('todo-box').hidden = passed;
    const activeDoc = model.active && model.active.id === activeId ? model.active : null;
    const against = activeDoc && activeDoc.id !== s.result_id ? activeDoc : null;
    redraw('values', JSON.stringify([s.result_id, against && against.id]), () => {
      const scale = typeof r.depth_scale === 'number'
        ? { value: r.depth_scale, sigma: r.sigma && r.sigma.depth_scale, estimated: !!r.depth_scale_estimated } : null;
      if (r.robot_from_sensor) valuesTable($('values'), r.robot_from_sensor, r.sigma, against, r.predicted_sigma, scale);
      else $('values').innerHTML = '';
    });
    // A pattern the gate `pattern_max_mm` found too large is drawn, but
    // its words say the calibration cannot rely on its correction.
    const tooLarge = (r.gate_checks || []).find((c) => c.gate === 'pattern_max_mm' && !c.passed);
    const tooLargeFor = tooLarge ? tooLarge.limit : null;
    redraw('warp', JSON.stringify([s.result_id, language, tooLargeFor]), () => showWarp(r.depth_pattern, s.result_id, tooLargeFor));
    activeHere = !!activeId && activeId === s.result_id;
    $('change').textContent = r.robot_from_sensor && !activeHere ? changeInWords(r.robot_from_sensor, activeDoc) : '';
    $('activeline').innerHTML = '';
    const replaced = !activeHere && s.result.replaced;
    if (activeHere) {
      const badge = document.createElement('span'); badge.className = 'active-badge'; badge.textContent = t('active');
      $('activeline').append(badge, t('since', when(s.active.activated)));
    } else if (replaced) {
      // It was active until someone made another active (a rollback): one
      // tap must not undo that. The history can still make it active again.
      $('activeline').textContent = t('wasActive', when(replaced.at), replaced.by, madeOn(replaced.by_id));
    } else {
      $('activeline').textContent = passed ? t('notActiveYet') : t('cannotBecomeActive');
    }
    $('resultid').textContent = s.result_id ? t('calibrationOf', madeOn(s.result_id)) : '';
    $('resultid').dataset.id = s.result_id || '';
    $('resultid').title = s.result_id || '';
    redraw('charts', 'result ' + s.result_id, () => charts(r.poses || [], s.of, false));
  } else if (s && !running && (s.interrupted || (s.error && !aborted))) {
    card.hidden = false;
    const cut = s.interrupted;
    $('todo-box').hidden = true;
    $('gates-box').hidden = true;
    verdict.textContent = cut ? t('interrupted') : t('noResult');
    verdict.className = cut ? 'interrupted' : 'failed';
    if (cut) {
      say(t(cut.task === 'check' ? 'cutOffCheck' : 'cutOff', cut.by, when(cut.started)));
      say(t('cutOffWatchdog'));
      say(s.startup_check === 'held_for_a_person' ? t('heldForPerson') : t('nothingMoves'));
    } else {
      say(s.error, true);
    }
    redraw('values', 'none', () => { $('values').innerHTML = ''; });
    redraw('warp', 'none', () => drawWarp(null));
    $('change').textContent = ''; $('activeline').textContent = ''; $('resultid').textContent = '';
    redraw('charts', 'none', () => charts([], 1, false));
  } else {
    card.hidden = true;
    if (running && !checking) redraw('charts', JSON.stringify(['running', s.provisional, s.of, s.pose]), () => charts(s.provisional || [], s.of || 1, true));
    else redraw('charts', 'none', () => charts([], 1, false));
  }
  const wasReplaced = !!(r && s.result.replaced) && !activeHere;
  $('accept').hidden = activeHere || wasReplaced || !(r && r.status === 'accepted');
  $('accept').disabled = lost || running || !r || r.status !== 'accepted' || !s.result_id || activeHere || wasReplaced;

  const c = model.confirm;
  $('confirm').hidden = !c;
  if (c) {
    $('confirm-text').textContent = t(c.kind === 'accept' ? 'confirmAccept' : 'confirmRollback', madeOn(c.id)) + t('otherPrograms');
    $('confirm').scrollIntoView({ block: 'nearest' });
  }
  $('confirm-yes').disabled = lost;

  // The active calibration and the history. The status names the active one
  // (every device the same); its document is loaded when that changes.
  const a = model.active && model.active.id === activeId ? model.active : null;
  $('active').textContent = activeId ? t('activeLine', madeOn(activeId), when(s.active.activated)) : t('noneYet');
  $('active').dataset.id = activeId || '';
  $('active').title = activeId || '';
  // The last check: running, how it ended, and (when it could not be made)
  // the verdict before it, which still stands.
  const line = $('checkline');
  const shownCheck = ck || lastVerdict;
  line.className = shownCheck ? shownCheck.outcome : '';
  const starter = (c) => c.started_by_service ? t('serviceStart') : c.by;
  let checkText = '';
  if (!shownCheck) checkText = a ? t('notChecked') : '';
  else if (shownCheck.outcome === 'running') checkText = t('checkingNow');
  else if (shownCheck.outcome === 'failed') {
    const held = shownCheck.started_by_service && s.startup_check === 'held_not_standing';
    checkText = t(held ? 'startCheckHeld' : 'checkFailed', when(shownCheck.started), (shownCheck.error || t('noReason')) + (shownCheck.error ? t('inEnglish') : ''));
    if (lastVerdict && lastVerdict.finished !== shownCheck.finished) checkText += ' ' + t('checkedAt', when(lastVerdict.finished), starter(lastVerdict), drift);
  } else checkText = t('checkedAt', when(shownCheck.finished), starter(shownCheck), shownCheck.outcome === 'drift');
  line.textContent = checkText;
  const reported = shownCheck && shownCheck.report ? shownCheck : lastVerdict;
  redraw('checks', JSON.stringify(reported && reported.report ? [reported.finished, reported.report.checks, language] : null), () => {
    const report = reported && reported.report;
    const unseen = report && report.not_checked.length ? [t('notSeen', report.not_checked.map((d) => t('directionNames')[d] || d).join(t('listJoin')))] : [];
    list($('checks'), checkFigures(report).concat(unseen));
  });
  redraw('history', JSON.stringify([model.history.slice(0, 20), activeId, lost || running]), () => {
    const history = $('history');
    history.innerHTML = '';
    if (!model.history.length) history.insertRow().insertCell().textContent = t('noCalibrations');
    for (const h of model.history.slice(0, 20)) {
      const row = history.insertRow();
      row.insertCell().textContent = when(h.created);
      row.insertCell().textContent = h.operator_rejected ? t('setAsideByOperator') : h.status === 'accepted' ? t('passedChecks') : h.status === 'rejected' ? t('failedChecks') : h.status;
      const cell = row.insertCell();
      if (h.id === activeId) {
        const badge = document.createElement('span'); badge.className = 'active-badge'; badge.textContent = t('active'); cell.appendChild(badge);
      } else if (h.status === 'accepted') {
        const b = document.createElement('button');
        b.className = 'small rollback'; b.textContent = activeId ? t('rollBackToThis') : t('makeActive');
        b.dataset.id = h.id; b.disabled = lost || running;
        b.onclick = () => { model.confirm = { kind: 'rollback', id: h.id }; render(); };
        cell.appendChild(b);
      }
      row.title = h.id;
    }
  });
}

// ---- what the camera sees ----------------------------------------------------

// The latest GET /api/view, and when it was read (its age runs on from then).
const view = { data: null, readAt: 0, loading: false };
async function loadView() {
  if (view.loading) return;
  view.loading = true;
  try {
    const r = await fetchWithin('/api/view', {}, 2000);
    if (r.ok) { view.data = await r.json(); view.readAt = Date.now(); }
  } catch (e) {
    // Contact is judged by the status polls and the heartbeat.
  } finally { view.loading = false; }
  renderView();
}
// The Kinect's fixed depth pattern a calibration found: one canvas pixel per
// cell, coloured by the depth error it causes at 2 m (red farther, blue
// nearer, white none, grey where no ground was seen), on a scale rounded up
// to 1, 2 or 5 × 10ⁿ mm.
function drawWarp(p, tooLargeFor) {
  const box = $('warp-box');
  box.hidden = !p;
  if (!p) return;
  const drawn = !!p.corrected && p.columns > 0 && p.rows > 0 && p.raw.length === p.columns * p.rows;
  for (const id of ['warp', 'warp-scale', 'warp-ticks']) $(id).hidden = !drawn;
  const mm = (v) => (Math.round(v * 10) / 10).toString();
  if (!drawn) {
    $('warp-words').textContent = typeof p.uncorrected_mm_at_2m !== 'number' ? t('warpNone')
      : t(p.uncorrected_fixed ? 'warpUncorrectedFixed' : 'warpUncorrected', mm(p.uncorrected_mm_at_2m));
    return;
  }
  const largest = Math.max(p.largest_mm_at_2m || 0, 1);
  const decade = Math.pow(10, Math.floor(Math.log10(largest)));
  const range = [1, 2, 5, 10].map((m) => m * decade).find((v) => v >= largest);
  const canvas = $('warp');
  canvas.width = p.columns; canvas.height = p.rows;
  const context = canvas.getContext('2d');
  const image = context.createImageData(p.columns, p.rows);
  const nearer = [33, 102, 172], farther = [178, 24, 43];
  for (let i = 0; i < p.raw.length; i++) {
    const raw = p.raw[i];
    let rgb = [190, 190, 190];
    if (typeof raw === 'number' && p.raw_per_inverse_depth) {
      const error = -4 * raw / p.raw_per_inverse_depth * 1000;
      const a = Math.max(-1, Math.min(1, error / range));
      const end = a < 0 ? nearer : farther;
      rgb = end.map((c) => Math.round(255 + (c - 255) * Math.abs(a)));
    }
    image.data.set([rgb[0], rgb[1], rgb[2], 255], 4 * i);
  }
  context.putImageData(image, 0, 0);
  $('warp-near').textContent = t('warpNearer', String(range));
  $('warp-far').textContent = t('warpFarther', String(range));
  $('warp-words').textContent = typeof tooLargeFor === 'number'
    ? t('warpTooLarge', mm(p.largest_mm_at_2m), String(Math.round(tooLargeFor)))
    : t('warpCorrected', mm(p.largest_mm_at_2m));
}

// The status leaves the pattern's cells out (it is polled every second);
// the stored calibration has them, fetched once per result.
async function showWarp(p, id, tooLargeFor) {
  if (p && p.corrected && p.raw.length === 0 && id) {
    // Until the cells come, nothing is claimed.
    $('warp-box').hidden = false;
    for (const part of ['warp', 'warp-scale', 'warp-ticks']) $(part).hidden = true;
    $('warp-words').textContent = '';
    try {
      const r = await fetchWithin('/api/calibrations/' + encodeURIComponent(id), {}, 5000);
      if (r.ok) {
        const stored = await r.json();
        if (stored.depth_pattern && drawn.get('warp') === JSON.stringify([id, language, tooLargeFor])) drawWarp(stored.depth_pattern, tooLargeFor);
      }
    } catch (e) {
      // The words stay; the picture comes with the next result.
    }
    return;
  }
  drawWarp(p, tooLargeFor);
}

// One canvas pixel per cell: grey by depth (lighter when nearer), green
// where the fit took the reading for the ground, black without a reading.
function drawView(v) {
  const canvas = $('view');
  canvas.width = v.width; canvas.height = v.height;
  const context = canvas.getContext('2d');
  const image = context.createImageData(v.width, v.height);
  for (let i = 0; i < v.width * v.height; i++) {
    const cm = v.depth_cm[i];
    const g = cm ? 60 + 170 * Math.max(0, Math.min(1, (500 - cm) / 450)) : 0;
    const rgb = !cm ? [0, 0, 0] : v.ground[i] ? [40 + 0.2 * g, 110 + 0.5 * g, 50 + 0.2 * g] : [g, g, g];
    image.data.set([rgb[0], rgb[1], rgb[2], 255], 4 * i);
  }
  context.putImageData(image, 0, 0);
}
function renderView() {
  const d = view.data;
  const v = d && d.view;
  const lost = model.contact === 'lost';
  if (v) redraw('view', d.seq, () => drawView(v));
  $('view').classList.toggle('stale', lost || !v);
  let whenText = t('viewNone');
  if (v) {
    const age = duration(((d.age_ms || 0) + (Date.now() - view.readAt)) / 1000);
    whenText = d.pose ? t('viewAtPose', d.pose, age) : t('viewAtRest', age);
  } else if (d && !d.live_at_rest) {
    whenText = t('viewOff');
  }
  $('view-when').textContent = whenText;
  const note = $('view-note');
  let warn = true;
  let text = '';
  if (lost && v) text = t('viewStale');
  else if (d && d.unavailable) text = t('viewUnavailable') + ' ' + d.unavailable;
  else if (v) {
    const readings = v.depth_cm.filter((c) => c > 0).length;
    const ground = v.ground.filter((g) => g === 1).length;
    if (readings < 0.1 * v.width * v.height) text = t('viewFewReadings');
    else if (v.no_ground) text = t('viewNoGround');
    else if (ground < 0.3 * readings) text = t('viewLittleGround');
    else { text = t('viewGroundShare', Math.round(100 * ground / readings)); warn = false; }
  }
  note.textContent = text;
  note.className = warn && text ? 'warn' : '';
  note.lang = d && d.unavailable && !lost ? 'en' : '';
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
// After each status read: an Abort waiting for contact goes now.
function afterStatus() {
  if (model.pendingAbort) flushPendingAbort();
}
function lose() {
  if (model.contact !== 'lost') { model.contact = 'lost'; model.lostSince = Date.now(); }
  render();
}
let retry = 1000;
// Reads of the status overlap (the timer's and each event's), on several
// connections; the answers can come back in another order than the daemon
// read them, even one asked for later. An answer older than the one shown
// (by the daemon's own count of its changes) is dropped: a stale "pose 3 of
// 52" must not replace "aborting…" (seen twice in CI under load; the order
// of asking, the first guard, did not hold the second time).
let shownRevision = null;
function isOlderThanShown(s) {
  return !!shownRevision && s.instance === shownRevision.instance && s.revision < shownRevision.revision;
}
async function refresh() {
  try {
    const r = await fetchWithin('/api/status', {}, 2000);
    if (!r.ok) { lose(); return false; }
    const s = await r.json();
    if (isOlderThanShown(s)) return true;
    shownRevision = { instance: s.instance, revision: s.revision };
    // A poll answered after a newer provisional event must not take the
    // live chart back: within a run it only grows.
    const before = model.status;
    if (before && s.state === 'running' && before.started === s.started && before.provisional
      && (!s.provisional || s.provisional.length < before.provisional.length)) s.provisional = before.provisional;
    const activeBefore = model.status && model.status.active ? model.status.active.id : null;
    model.status = s;
    model.statusAt = Date.now();
    heard();
    retry = 1000;
    // Another device accepted or rolled back: the store is read again.
    const activeNow = s.active ? s.active.id : null;
    if (activeNow !== activeBefore || (activeNow && (!model.active || model.active.id !== activeNow))) loadStore();
    render();
    afterStatus();
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

// The live stream. With the token, a one-use ticket makes it the
// operator's: no stream opened without the token can take its place under a
// flood (an EventSource cannot send the token itself).
let events = null;
async function streamUrl() {
  const token = tokenField.value.trim();
  if (!token) return '/api/events';
  try {
    const r = await fetchWithin('/api/stream-ticket', { method: 'POST', headers: { 'Authorization': 'Bearer ' + token } }, 2000);
    if (r.ok) {
      const { ticket } = await r.json();
      if (ticket) return '/api/events?ticket=' + encodeURIComponent(ticket);
    }
  } catch (e) {
    // No contact: the status polls say so; the stream is tried as anyone's.
  }
  return '/api/events';
}
async function listen() {
  events = new EventSource(await streamUrl());
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
    if (e.type === 'ground_seen') { loadView(); return; }
    if (e.type === 'provisional' && model.status) {
      model.status.provisional = e.poses;
      render();
    } else {
      if (e.type === 'stored' || e.type === 'failed' || e.type === 'checked' || e.type === 'activated') loadStore();
      refresh();
    }
  };
}

$('language').onchange = () => {
  language = $('language').value;
  localStorage.setItem('groundcal-language', language);
  applyLanguage();
  render();
  renderView();
};
applyLanguage();
listen();
refresh();
loadView();
setInterval(() => { refresh(); loadView(); }, 1000);
// Silence: no heartbeat, no event and no status for SILENCE_MS.
setInterval(() => {
  if (model.contact === 'ok' && Date.now() - model.heardAt > SILENCE_MS) lose();
  else if (model.contact === 'lost') render();
}, 200);
