// The terminal page's script (page.html): served from the daemon itself,
// as the page's Content-Security-Policy allows no inline script.
'use strict';
const $ = (id) => document.getElementById(id);
const tokenField = $('token');
tokenField.value = localStorage.getItem('groundcal-token') || '';
tokenField.addEventListener('input', () => localStorage.setItem('groundcal-token', tokenField.value.trim()));
let status = null;

async function call(method, url) {
  const headers = { 'Authorization': 'Bearer ' + tokenField.value.trim(), 'X-Groundcal-Client': 'terminal page' };
  const r = await fetch(url, { method, headers });
  let body = {};
  try { body = await r.json(); } catch (e) { body = {}; }
  $('message').style.color = r.ok ? '#2e7d32' : '#c62828';
  if (!r.ok) { $('message').textContent = body.error || ('HTTP ' + r.status); } else { $('message').textContent = ''; }
  refresh();
  return r.ok;
}
$('calibrate').onclick = () => call('POST', '/api/calibrations');
// Between Abort and the session's end the robot halts and walks home, which
// takes seconds on a real robot: the page says so.
let aborting = false;
$('abort').onclick = async () => {
  aborting = true;
  $('progress').textContent = 'aborting…';
  $('robot').textContent = 'halting the robot and sending it home';
  if (!await call('POST', '/api/calibrations/current/abort')) aborting = false;
};
$('accept').onclick = async () => {
  if (status && status.result_id && await call('POST', '/api/calibrations/' + status.result_id + '/accept')) {
    $('message').textContent = 'accepted: ' + status.result_id + ' is now active';
  }
};

// poses: [{index, value, used}]; the x axis runs over pose 1..count, so a
// chart filled during a run grows from the left.
function chart(svg, poses, count, label) {
  while (svg.firstChild) svg.removeChild(svg.firstChild);
  const pts = poses.filter((p) => typeof p.value === 'number');
  svg.dataset.points = String(pts.length);
  if (!pts.length) return;
  const max = Math.max(...pts.map((p) => p.value), 1e-9);
  const n = Math.max(count - 1, 1);
  const x = (p) => ((p.index - 1) / n * 290 + 5).toFixed(1);
  const y = (p) => (95 - p.value / max * 85).toFixed(1);
  const ns = 'http://www.w3.org/2000/svg';
  const used = pts.filter((p) => p.used);
  const line = document.createElementNS(ns, 'polyline');
  line.setAttribute('points', used.map((p) => x(p) + ',' + y(p)).join(' '));
  line.setAttribute('fill', 'none'); line.setAttribute('stroke', '#1a6fd1'); line.setAttribute('stroke-width', '1.5');
  svg.appendChild(line);
  for (const p of pts) {
    const c = document.createElementNS(ns, 'circle');
    c.setAttribute('cx', x(p)); c.setAttribute('cy', y(p)); c.setAttribute('r', p.used ? '2' : '3');
    c.setAttribute('fill', p.used ? '#1a6fd1' : 'none'); c.setAttribute('stroke', p.used ? 'none' : '#c0392b');
    svg.appendChild(c);
  }
  const t = document.createElementNS(ns, 'text');
  t.setAttribute('x', '5'); t.setAttribute('y', '10'); t.setAttribute('font-size', '9');
  t.textContent = label + 'max ' + max.toPrecision(3) + (used.length < pts.length ? ' (red: set aside)' : '');
  svg.appendChild(t);
}

// θ and e_d per pose: the result's, or while running the provisional solve's.
function charts(poses, count, label) {
  // Pose ids may have gaps (a replayed recording): the axis reaches the last.
  count = Math.max(count || 1, ...poses.map((p) => p.index));
  chart($('theta'), poses.map((p) => ({ index: p.index, value: p.theta_deg, used: p.used })), count, label);
  chart($('ed'), poses.map((p) => ({ index: p.index, value: p.e_d_mm, used: p.used })), count, label);
}

function show(s) {
  status = s;
  const running = s.state === 'running';
  $('calibrate').disabled = running;
  $('abort').disabled = !running;
  const stoppedAtHome = !running && /^aborted/.test(s.robot || '') && /stands at the home stance/.test(s.robot || '');
  if (!running) aborting = false;
  $('progress').textContent = running
    ? (aborting ? 'aborting…' : 'pose ' + (s.pose || 0) + ' of ' + (s.of || '?'))
    : (stoppedAtHome ? 'at home' : 'idle');
  $('robot').textContent = running && aborting
    ? 'halting the robot and sending it home'
    : s.robot + (s.by ? ' — started by ' + s.by : '');
  // What matters for safety stands out: a robot that may not have stopped.
  const unsafe = [s.robot, s.error].find((t) => /could not halt|could not send it home/.test(t || ''));
  $('safety').hidden = !unsafe;
  $('safety').textContent = unsafe ? 'The robot may not have stopped: ' + unsafe + '. Check it before anything else.' : '';
  $('hardware').textContent = s.hardware ? 'hardware at start: ' + s.hardware : '';
  const r = s.result;
  $('accept').disabled = running || !r || r.status !== 'accepted' || !s.result_id;
  if (r && !running) {
    $('verdict').textContent = r.status === 'accepted' ? 'Accepted' : 'Rejected';
    $('verdict').className = r.status;
    $('reasons').innerHTML = '';
    for (const reason of r.reasons || []) { const li = document.createElement('li'); li.textContent = reason; $('reasons').appendChild(li); }
    $('resultid').textContent = s.result_id ? 'result ' + s.result_id : '';
    const poses = r.poses || [];
    charts(poses, Math.max(s.of || 0, ...poses.map((p) => p.index)), '');
  } else if (running) {
    $('verdict').textContent = ''; $('verdict').className = ''; $('reasons').innerHTML = ''; $('resultid').textContent = '';
    charts(s.provisional || [], s.of || 1, 'so far: ');
  } else if (s.error) {
    charts([], 1, '');
    $('verdict').textContent = s.interrupted ? 'Interrupted' : 'No result'; $('verdict').className = 'rejected';
    $('reasons').innerHTML = ''; const li = document.createElement('li'); li.textContent = s.error; $('reasons').appendChild(li);
  }
}

// Contact with the daemon: a page that cannot reach it must not look alive.
// Lost when a status request fails or the event stream breaks; found again
// when a status request succeeds (both retry by themselves).
let lostSince = null;
function contactLost() {
  if (lostSince === null) { lostSince = Date.now(); showContact(); }
}
function contactFound() {
  if (lostSince !== null) { lostSince = null; showContact(); }
}
function showContact() {
  const banner = $('lost');
  if (lostSince === null) { banner.hidden = true; return; }
  const seconds = Math.round((Date.now() - lostSince) / 1000);
  const wasRunning = status && status.state === 'running';
  banner.textContent = 'No contact with groundcal for ' + seconds + ' s: this page shows its last state, and its buttons cannot reach the robot.'
    + (wasRunning ? ' A calibration was running: the robot\'s own watchdog stops the body within 1 s of losing its link.' : '')
    + ' Reconnecting…';
  banner.hidden = false;
  for (const id of ['calibrate', 'abort', 'accept']) $(id).disabled = true;
}
setInterval(() => { if (lostSince !== null) showContact(); }, 1000);

async function refresh() {
  try {
    const r = await fetch('/api/status');
    if (!r.ok) { contactLost(); return; }
    const s = await r.json();
    contactFound();
    show(s);
  } catch (e) { contactLost(); }
}
const events = new EventSource('/api/events');
events.onerror = () => { contactLost(); refresh(); };
events.onopen = () => refresh();
events.onmessage = (m) => {
  let e; try { e = JSON.parse(m.data); } catch (x) { return; }
  if (e.type === 'provisional') {
    charts(e.poses, (status && status.of) || e.poses.length, 'so far: ');
  } else if ((e.type === 'moving' || e.type === 'capturing' || e.type === 'pose_done') && !aborting) {
    $('progress').textContent = 'pose ' + e.index + ' of ' + e.of;
    $('robot').textContent = e.type === 'pose_done' ? (e.ok ? 'ground fitted' : e.error) : e.type;
  } else {
    refresh();
  }
};
refresh();
setInterval(refresh, 2000);
