// A preview of a groundcal session's MCAP file as Foxglove's layout
// (docs/foxglove-layout.json) shows it: the depth image and the 3D view of
// the ground, the body, its feet and the sensor with the ground it found.
// The file is read with Foxglove's own libraries (@mcap/core's indexed
// reader, @foxglove/rosmsg and @foxglove/rosmsg2-serialization), not
// groundcal's code; the picture is drawn by this script in headless
// Chromium (it is not Foxglove).
//
//   node tests/browser/mcap-preview.mjs SESSION.mcap SCREENSHOT.png [POSE]
//
// Saves SCREENSHOT.png (phone, 390 px wide) and SCREENSHOT-desktop.png
// (1280 px). Prints one JSON line: the messages decoded per topic, the pose
// shown, and what was drawn. Exits 1 when a message does not decode, a
// topic the layout needs is missing, or the page shows an error.

import { readFileSync } from 'node:fs';
import { open } from 'node:fs/promises';
import { resolve } from 'node:path';

import { McapIndexedReader } from '@mcap/core';
import { parse } from '@foxglove/rosmsg';
import { MessageReader } from '@foxglove/rosmsg2-serialization';

import { deadline, launch } from './chromium.mjs';

const [mcapArg, pngArg, poseArg] = process.argv.slice(2);
if (!mcapArg || !pngArg) {
  console.error('usage: node mcap-preview.mjs SESSION.mcap SCREENSHOT.png [POSE]');
  process.exit(2);
}
deadline('mcap-preview.mjs', 120);

const fail = (message) => {
  console.error(`mcap-preview: ${message}`);
  process.exit(1);
};

// ---- Reading, with Foxglove's libraries --------------------------------

const handle = await open(resolve(mcapArg), 'r');
const { size } = await handle.stat();
const readable = {
  size: async () => BigInt(size),
  read: async (offset, length) => {
    const buffer = new Uint8Array(Number(length));
    await handle.read(buffer, 0, Number(length), Number(offset));
    return buffer;
  },
};
const reader = await McapIndexedReader.Initialize({ readable });
const readers = new Map();
for (const [id, channel] of reader.channelsById) {
  const schema = reader.schemasById.get(channel.schemaId);
  if (!schema || schema.encoding !== 'ros2msg' || channel.messageEncoding !== 'cdr') {
    fail(`${channel.topic}: schema ${schema?.encoding} / ${channel.messageEncoding}, not ros2msg / cdr`);
  }
  const text = new TextDecoder().decode(schema.data);
  readers.set(id, { topic: channel.topic, reader: new MessageReader(parse(text, { ros2: true })) });
}
const counts = {};
const byTopic = {};
for await (const message of reader.readMessages()) {
  const { topic, reader: decode } = readers.get(message.channelId);
  let decoded;
  try {
    decoded = decode.readMessage(message.data);
  } catch (error) {
    fail(`${topic} at ${message.logTime}: ${error.message}`);
  }
  counts[topic] = (counts[topic] ?? 0) + 1;
  (byTopic[topic] ??= []).push({ time: message.logTime, message: decoded });
}
await handle.close();
// Every topic docs/foxglove-layout.json shows is in the file, and the
// plotted fields are in its messages.
const layout = JSON.parse(readFileSync(new URL('../../docs/foxglove-layout.json', import.meta.url), 'utf8'));
const shownTopics = new Set(['/tf', '/tf_static']);
for (const panel of Object.values(layout.configById)) {
  for (const topic of Object.keys(panel.topics ?? {})) shownTopics.add(topic);
  for (const key of ['imageTopic', 'calibrationTopic']) if (panel.imageMode?.[key]) shownTopics.add(panel.imageMode[key]);
  if (panel.topicPath) shownTopics.add(panel.topicPath);
  for (const { value } of panel.paths ?? []) {
    const [topic, field] = value.split('.');
    shownTopics.add(topic);
    if (byTopic[topic] && !(field in byTopic[topic][0].message)) fail(`the layout plots ${value}, which ${topic}'s messages lack`);
  }
}
for (const topic of shownTopics) {
  if (!counts[topic]) fail(`no message on ${topic}, which the layout shows`);
}

// ---- The pose shown and its geometry (ground frame, z up) --------------

const fits = byTopic['/groundcal/pose_fit'].map((m) => m.message);
const shown = poseArg ? Number(poseArg) : fits.find((f) => f.used)?.pose_index ?? fits[0].pose_index;
const fitIndex = fits.findIndex((f) => f.pose_index === shown);
if (fitIndex < 0) fail(`no pose ${shown} in the file`);
const fit = fits[fitIndex];
const fitTime = byTopic['/groundcal/pose_fit'][fitIndex].time;

const quaternionMatrix = ({ x, y, z, w }) => [
  [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
];
const pose = (t) => ({ r: quaternionMatrix(t.transform.rotation), t: [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z] });
const apply = (p, v) => p.r.map((row, i) => row[0] * v[0] + row[1] * v[1] + row[2] * v[2] + p.t[i]);
const compose = (a, b) => ({
  r: a.r.map((row) => [0, 1, 2].map((j) => row[0] * b.r[0][j] + row[1] * b.r[1][j] + row[2] * b.r[2][j])),
  t: apply(a, b.t),
});

// The last /tf at or before the pose's fit: the body and feet of this pose.
const tfs = byTopic['/tf'].filter((m) => m.time <= fitTime);
const tf = (tfs.at(-1) ?? byTopic['/tf'][0]).message.transforms;
const groundFromBody = pose(tf.find((t) => t.header.frame_id === 'ground' && t.child_frame_id === 'base_link'));
const feet = tf.filter((t) => t.child_frame_id.startsWith('foot_')).map((t) => apply(groundFromBody, pose(t).t));
const mount = byTopic['/tf_static'][0].message.transforms.find((t) => t.child_frame_id === 'camera_depth_optical_frame');
const groundFromCamera = compose(groundFromBody, pose(mount));

const cloudPoints = (cloud) => {
  const view = new DataView(cloud.data.buffer, cloud.data.byteOffset, cloud.data.byteLength);
  const field = (name) => cloud.fields.find((f) => f.name === name).offset;
  const [ox, oy, oz] = ['x', 'y', 'z'].map(field);
  const points = [];
  for (let k = 0; k < cloud.width * cloud.height; k++) {
    const at = k * cloud.point_step;
    const little = !cloud.is_bigendian;
    points.push(apply(groundFromCamera, [view.getFloat32(at + ox, little), view.getFloat32(at + oy, little), view.getFloat32(at + oz, little)]));
  }
  return points;
};
const atPose = (topic) => byTopic[topic]?.find((m) => m.time === fitTime)?.message;
const inliers = atPose('/groundcal/ground/inliers');
const measured = atPose('/groundcal/ground/measured');
const predicted = atPose('/groundcal/ground/predicted');

// The pose's last depth image before its fit.
const images = byTopic['/camera/depth/image_raw'].filter((m) => m.time <= fitTime);
const image = (images.at(-1) ?? byTopic['/camera/depth/image_raw'][0]).message;
if (image.encoding !== '16UC1') fail(`${image.encoding}: not 16UC1`);
const millimetres = new Uint16Array(image.width * image.height);
const pixels = new DataView(image.data.buffer, image.data.byteOffset, image.data.byteLength);
for (let k = 0; k < millimetres.length; k++) millimetres[k] = pixels.getUint16(2 * k, !image.is_bigendian);

const scene = {
  pose: shown,
  used: fit.used,
  theta: fit.theta_deg,
  eD: fit.e_d_mm,
  reason: fit.reason,
  poses: fits.length,
  body: groundFromBody.t,
  bodyAxes: groundFromBody.r,
  feet,
  camera: groundFromCamera,
  inliers: inliers ? cloudPoints(inliers) : [],
  measured: measured ? cloudPoints(measured) : [],
  predicted: predicted ? cloudPoints(predicted) : [],
  image: { width: image.width, height: image.height, mm: Buffer.from(millimetres.buffer).toString('base64') },
  topics: Object.keys(counts).length,
  messages: Object.values(counts).reduce((a, b) => a + b, 0),
};

// ---- The page --------------------------------------------------------------

const PAGE = `<!doctype html><html><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>
  body { margin: 0; font: 15px/1.4 system-ui, sans-serif; background: #14171c; color: #e8eaed; }
  main { display: flex; flex-wrap: wrap; gap: 12px; padding: 12px; }
  section { flex: 1 1 360px; min-width: 0; background: #1d2128; border-radius: 8px; padding: 10px; }
  h1 { font-size: 17px; margin: 12px 12px 0; }
  h2 { font-size: 15px; margin: 0 0 6px; }
  canvas { width: 100%; height: auto; display: block; border-radius: 4px; background: #000; }
  .scale { display: flex; justify-content: space-between; font-size: 13px; color: #b0b6bf; }
  .bar { height: 10px; border-radius: 3px; margin: 4px 0 0; }
  .legend span { display: inline-block; margin-right: 12px; font-size: 13px; }
  .legend i { display: inline-block; width: 10px; height: 10px; border-radius: 5px; margin-right: 4px; vertical-align: -1px; }
  p { margin: 6px 0 0; font-size: 13px; color: #b0b6bf; }
</style></head><body>
<h1 id="title"></h1>
<main>
  <section><h2>Depth image, <code>/camera/depth/image_raw</code> (16UC1)</h2>
    <canvas id="depth"></canvas>
    <div class="bar" id="bar"></div><div class="scale"><span>0.5 m</span><span>depth (the trusted range)</span><span>5.0 m</span></div>
    <p>Black: no reading.</p></section>
  <section><h2>3D: ground, body, feet and sensor</h2>
    <canvas id="view" width="720" height="540"></canvas>
    <div class="legend">
      <span><i style="background:#5dd39e"></i>ground the fit took</span>
      <span><i style="background:#f6c945"></i>feet</span>
      <span><i style="background:#7aa7ff"></i>sensor</span>
      <span><i style="background:#ff7a7a"></i>ground predicted</span></div>
    <p id="fit"></p></section>
</main>
<script>
const scene = ${JSON.stringify(scene)};
// Turbo, in 9 stops (Google's, 2019), interpolated.
const TURBO = [[48,18,59],[70,107,227],[40,187,236],[50,242,152],[164,252,60],[237,208,58],[251,128,34],[205,46,6],[122,4,3]];
function turbo(t) {
  t = Math.min(1, Math.max(0, t)) * (TURBO.length - 1);
  const k = Math.min(TURBO.length - 2, Math.floor(t)), f = t - k;
  return TURBO[k].map((c, i) => Math.round(c + f * (TURBO[k + 1][i] - c)));
}
document.getElementById('title').textContent =
  'groundcal session: pose ' + scene.pose + ' of ' + scene.poses + (scene.used ? '' : ' (set aside)');
document.getElementById('bar').style.background =
  'linear-gradient(to right,' + TURBO.map((c) => 'rgb(' + c + ')').join(',') + ')';
document.getElementById('fit').textContent =
  'θ ' + scene.theta.toFixed(4) + '°, e_d ' + scene.eD.toFixed(2) + ' mm' + (scene.reason ? ' — ' + scene.reason : '') +
  '. ' + scene.messages + ' messages on ' + scene.topics + ' topics, read with Foxglove\\'s own decoders.';

// The depth image.
{
  const { width, height, mm } = scene.image;
  const bytes = Uint8Array.from(atob(mm), (c) => c.charCodeAt(0));
  const depth = new Uint16Array(bytes.buffer);
  const canvas = document.getElementById('depth');
  canvas.width = width; canvas.height = height;
  const context = canvas.getContext('2d');
  const picture = context.createImageData(width, height);
  for (let k = 0; k < depth.length; k++) {
    const [r, g, b] = depth[k] ? turbo((depth[k] - 500) / 4500) : [0, 0, 0];
    picture.data.set([r, g, b, 255], 4 * k);
  }
  context.putImageData(picture, 0, 0);
}

// The 3D view: an orbit camera looking at the body from behind and above.
{
  const canvas = document.getElementById('view');
  const context = canvas.getContext('2d');
  const target = [scene.body[0] + 0.9, scene.body[1], 0.15];
  const azimuth = -2.2, elevation = 0.45, distance = 3.4, focal = 640;
  const eye = [target[0] + distance * Math.cos(elevation) * Math.cos(azimuth),
               target[1] + distance * Math.cos(elevation) * Math.sin(azimuth),
               target[2] + distance * Math.sin(elevation)];
  const sub = (a, b) => a.map((v, i) => v - b[i]);
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const unit = (a) => { const n = Math.hypot(...a); return a.map((v) => v / n); };
  const forward = unit(sub(target, eye)), right = unit(cross(forward, [0, 0, 1])), up = cross(right, forward);
  const project = (p) => {
    const d = sub(p, eye), z = dot(d, forward);
    return z > 0.05 ? [canvas.width / 2 + focal * dot(d, right) / z, canvas.height / 2 - focal * dot(d, up) / z] : null;
  };
  const line = (a, b, colour, width = 2) => {
    const [p, q] = [project(a), project(b)];
    if (!p || !q) return;
    context.strokeStyle = colour; context.lineWidth = width;
    context.beginPath(); context.moveTo(...p); context.lineTo(...q); context.stroke();
  };
  const dots = (points, colour, radius) => {
    context.fillStyle = colour;
    for (const point of points) {
      const p = project(point);
      if (p) { context.beginPath(); context.arc(p[0], p[1], radius, 0, 2 * Math.PI); context.fill(); }
    }
  };
  context.fillStyle = '#0d0f13'; context.fillRect(0, 0, canvas.width, canvas.height);
  // The ground grid, 0.25 m, from behind the body to 4 m ahead of it.
  for (let k = -8; k <= 16; k++) {
    const x = scene.body[0] + k * 0.25;
    line([x, scene.body[1] - 2, 0], [x, scene.body[1] + 2, 0], '#2b313b', 1);
  }
  for (let k = -8; k <= 8; k++) {
    const y = scene.body[1] + k * 0.25;
    line([scene.body[0] - 2, y, 0], [scene.body[0] + 4, y, 0], '#2b313b', 1);
  }
  dots(scene.predicted, 'rgba(255,122,122,0.55)', 1.6);
  dots(scene.inliers, 'rgba(93,211,158,0.8)', 1.4);
  // The body: its axes and its legs to the feet.
  for (const foot of scene.feet) line(scene.body, foot, '#c9ced6', 3);
  dots(scene.feet, '#f6c945', 6);
  const axis = (origin, r, column, length, colour) =>
    line(origin, origin.map((v, i) => v + length * r[i][column]), colour, 3);
  axis(scene.body, scene.bodyAxes, 0, 0.25, '#ff5555');
  axis(scene.body, scene.bodyAxes, 1, 0.25, '#55dd55');
  axis(scene.body, scene.bodyAxes, 2, 0.25, '#5588ff');
  // The sensor: its frustum (0.35 m deep) along the optical z.
  const camera = scene.camera, at = (v) => camera.r.map((row, i) => row[0] * v[0] + row[1] * v[1] + row[2] * v[2] + camera.t[i]);
  const corners = [[-0.27, -0.2, 0.35], [0.27, -0.2, 0.35], [0.27, 0.2, 0.35], [-0.27, 0.2, 0.35]].map(at);
  for (let k = 0; k < 4; k++) { line(camera.t, corners[k], '#7aa7ff', 2); line(corners[k], corners[(k + 1) % 4], '#7aa7ff', 2); }
  dots([camera.t], '#7aa7ff', 5);
  window.drawn = { inliers: scene.inliers.length, predicted: scene.predicted.length, feet: scene.feet.length };
}
</script></body></html>`;

const VIEWPORTS = [
  { name: 'phone', viewport: { width: 390, height: 844 }, isMobile: true, hasTouch: true, deviceScaleFactor: 2 },
  { name: 'desktop', viewport: { width: 1280, height: 900 }, isMobile: false, hasTouch: false, deviceScaleFactor: 1 },
];
const problems = [];
let drawn = null;
for (const { name, ...options } of VIEWPORTS) {
  const { context, close } = await launch(options);
  try {
    const page = context.pages()[0] ?? (await context.newPage());
    page.on('pageerror', (error) => problems.push(`${name}: page error: ${error.message}`));
    page.on('console', (m) => m.type() === 'error' && problems.push(`${name}: console error: ${m.text()}`));
    await page.setContent(PAGE, { waitUntil: 'load', timeout: 30_000 });
    drawn = await page.evaluate(() => window.drawn);
    const wide = await page.evaluate(() => document.documentElement.scrollWidth > window.innerWidth);
    if (wide) problems.push(`${name}: the page is wider than the screen`);
    const path = name === 'phone' ? resolve(pngArg) : resolve(pngArg).replace(/(\.png)?$/, `-${name}.png`);
    await page.screenshot({ path, fullPage: true });
  } finally {
    await close();
  }
}
if (!drawn || drawn.feet !== 6 || drawn.inliers === 0) problems.push(`the 3D view drew ${JSON.stringify(drawn)}`);
// The ground the camera saw, through the mount and the body pose, lies
// where the feet stand (z = 0 of the ground frame).
const heights = scene.inliers.map((p) => p[2]).sort((a, b) => a - b);
const median = heights.length ? heights[heights.length >> 1] : NaN;
if (!(Math.abs(median) < 0.005)) problems.push(`the ground found lies ${median} m from the feet's plane`);
if (scene.feet.some((f) => Math.abs(f[2]) > 0.005)) problems.push(`a foot is off the ground: ${scene.feet.map((f) => f[2])}`);
console.log(JSON.stringify({ counts, pose: shown, drawn, problems, layout_topics: [...shownTopics].sort(), ground_height_m: heights.length ? [heights[0], heights[heights.length >> 1], heights.at(-1)] : null, feet_height_m: scene.feet.map((f) => f[2]) }));
process.exit(problems.length ? 1 : 0);
