// Drives the `groundcal serve` terminal page in headless Chromium as an
// operator would on a phone (tests/serve_browser.rs):
//
//   node tests/browser/serve.mjs URL TOKEN SCREENSHOT_DIR
//
// Types the token, presses Calibrate: a confirmation says how long the robot
// will move and to keep clear, and Cancel sends nothing; pressed again and
// confirmed, watches the bar, the time left, the
// step in words and the live θ/e_d chart fill in, waits for the verdict with
// the six values, presses Accept and confirms: the result shows as Active. A
// second calibration is accepted, then the first is rolled back to from the
// history. A third is aborted: "aborting…", then "aborted: at home". Last the same
// page at pad size (1024×1366) must show two columns. Checks: no console
// error, no page error, no request leaving the server (the page works
// offline), no page wider than the screen. Saves serve-1-idle.png, serve-1b-confirm-calibrate.png,
// serve-2-progress.png, serve-3-verdict.png, serve-3b-confirm.png,
// serve-4-accepted.png, serve-8-rollback.png, serve-7-aborted.png and
// serve-9-pad.png. Prints one JSON line of what it saw; exits 0 when every
// check passes, 1 otherwise, 2 on bad usage.

import { resolve } from 'node:path';

import { deadline, launch } from './chromium.mjs';

const [url, token, shotDir] = process.argv.slice(2);
if (!url || !token || !shotDir) {
  console.error('usage: node serve.mjs URL TOKEN SCREENSHOT_DIR');
  process.exit(2);
}
deadline('serve.mjs', 240);

const origin = new URL(url).origin;
const problems = [];
const seen = {};
const shot = (page, name) => page.screenshot({ path: resolve(shotDir, `serve-${name}.png`), fullPage: true });
let browser;
try {
  browser = await launch({
    viewport: { width: 390, height: 844 },
    isMobile: true,
    hasTouch: true,
    deviceScaleFactor: 2,
  });
  const { context } = browser;
  await context.route('**/*', (route) => {
    const requested = route.request().url();
    if (requested.startsWith(origin) || requested.startsWith('data:')) return route.continue();
    problems.push(`the page requested ${requested}`);
    return route.abort();
  });
  const page = context.pages()[0] ?? (await context.newPage());
  page.on('console', (m) => {
    if (m.type() === 'error') problems.push(`console error: ${m.text()}`);
  });
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));

  await page.goto(url, { waitUntil: 'load', timeout: 30_000 });
  await page.waitForFunction(() => document.getElementById('progress').textContent === 'idle');
  seen.idleCards = await page.$$eval('section.card:not([hidden])', (n) => n.map((c) => c.id));
  await shot(page, '1-idle');

  const text = (id) => page.locator('#' + id).innerText();
  const overflow = async (where) => {
    const wider = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
    if (wider > 1) problems.push(`${where}: the page is ${wider} px wider than the screen`);
  };
  // Waits for a calibration's verdict and returns its id.
  const verdict = async () => {
    await page.waitForFunction(() => ['Passed its checks', 'Failed its checks'].includes(document.getElementById('verdict').textContent)
      && !document.getElementById('result').hidden, null, { timeout: 180_000 });
    return page.$eval('#resultid', (e) => e.dataset.id);
  };
  // Every POST the page sends (Cancel must send none).
  const posts = [];
  // (The live stream's one-use ticket is a POST too, and moves nothing.)
  page.on('request', (r) => { if (r.method() === 'POST' && !r.url().endsWith('/api/stream-ticket')) posts.push(r.url()); });
  // Presses Calibrate and confirms that the robot may move.
  const calibrate = async () => {
    await page.click('#calibrate');
    await page.waitForSelector('#confirm-run:not([hidden])');
    await page.click('#confirm-run-yes');
  };
  // Presses a button that asks for confirmation, then confirms.
  const confirmed = async (selector, shotName) => {
    await page.click(selector);
    await page.waitForSelector('#confirm:not([hidden])');
    const question = await text('confirm-text');
    if (shotName) await shot(page, shotName);
    await page.click('#confirm-yes');
    return question;
  };

  // Without a token nothing can start: Calibrate says so first, before any
  // question about the robot.
  await page.click('#calibrate');
  seen.noToken = {
    message: await text('message'),
    confirmHidden: await page.$eval('#confirm-run', (e) => e.hidden),
    tokenOpen: await page.$eval('#token-card', (d) => d.open),
  };
  if (!await page.$eval('#token-card', (d) => d.open)) await page.click('#token-card summary');
  await page.fill('#token', token);
  // Calibrate asks first; Cancel sends nothing and nothing starts.
  await page.click('#calibrate');
  await page.waitForSelector('#confirm-run:not([hidden])');
  seen.confirmCalibrate = await text('confirm-run-text');
  await shot(page, '1b-confirm-calibrate');
  await page.click('#confirm-run-no');
  await page.waitForTimeout(1500);
  seen.cancelled = {
    posts: posts.length,
    confirmHidden: await page.$eval('#confirm-run', (e) => e.hidden),
    state: await page.evaluate(async () => (await (await fetch('/api/status')).json()).state),
  };
  await calibrate();
  await page.waitForFunction(() => /pose [1-9]\d* of \d+/.test(document.getElementById('progress').textContent), null, { timeout: 60_000 });
  seen.step = await text('step');
  // The motion in words ("rolled 20° right, …"): every pose of the paper's
  // schedule rolls the body.
  seen.motion = await (await page.waitForFunction(() => {
    const step = document.getElementById('step').textContent;
    return /moving the body \(rolled/.test(step) && step;
  }, null, { timeout: 60_000 })).jsonValue();
  // The live chart: θ and e_d of the provisional solve while poses go by,
  // and the time left once poses are done.
  await page.waitForFunction(() => Number(document.getElementById('theta').dataset.points || 0) >= 6
    && /left/.test(document.getElementById('times').textContent)
    && document.getElementById('result').hidden, null, { timeout: 60_000 });
  seen.livePoints = await page.$$eval('#theta circle', (n) => n.length);
  seen.liveProgress = await text('progress');
  seen.liveTitle = await text('charts-title');
  seen.times = await text('times');
  seen.bar = await page.$eval('#bar-fill', (e) => parseFloat(e.style.width));
  seen.gateLines = await page.$$eval('svg line.gate, svg text', (n) => n.filter((e) => /gate/.test(e.getAttribute('class') || e.textContent)).length);
  seen.axisLabels = await page.$$eval('#theta text', (n) => n.map((e) => e.textContent));
  await shot(page, '2-progress');

  const first = await verdict();
  seen.verdict = await text('verdict');
  seen.points = await page.$$eval('#theta circle', (n) => n.length);
  seen.values = await page.$$eval('#values tr', (rows) => rows.map((r) => r.innerText));
  seen.predicted = await page.$$eval('#values .predicted', (n) => n.length);
  seen.gates = await page.$$eval('#gates li', (n) => n.map((e) => e.textContent));
  seen.gatesTitle = await text('gates-title');
  seen.notActiveYet = await text('activeline');
  // No pattern on the simulated Kinect: the warp card says so in words and
  // shows no picture, no scale and no ticks (an empty frame and a lone "0"
  // were shown until CSS let [hidden] win).
  seen.warp = await page.evaluate(() => ({
    words: document.getElementById('warp-words').textContent,
    shown: ['warp', 'warp-scale', 'warp-ticks'].filter((id) => document.getElementById(id).getClientRects().length > 0),
  }));
  await shot(page, '3-verdict');

  seen.confirmQuestion = await confirmed('#accept', '3b-confirm');
  await page.waitForFunction(() => /Active/.test(document.getElementById('activeline').textContent), null, { timeout: 30_000 });
  seen.activeLine = await text('activeline');
  seen.acceptHidden = await page.$eval('#accept', (b) => b.hidden);
  seen.message = await text('message');
  seen.storedToken = await page.evaluate(() => localStorage.getItem('groundcal-token'));
  await overflow('accepted');
  await shot(page, '4-accepted');

  // A second calibration, accepted; then roll back to the first. Its
  // question says how long the first one took here; from the moment it is
  // confirmed the page says it is starting, never the last run's end.
  await page.click('#calibrate');
  await page.waitForSelector('#confirm-run:not([hidden])');
  seen.confirmSecond = await text('confirm-run-text');
  await page.click('#confirm-run-yes');
  seen.titleAtStart = await text('progress');
  await page.waitForFunction(() => /pose \d+ of \d+/.test(document.getElementById('progress').textContent)
    && document.getElementById('result').hidden, null, { timeout: 60_000 });
  const second = await verdict();
  seen.change = await text('change');
  await confirmed('#accept');
  await page.waitForFunction((id) => document.getElementById('active').dataset.id === id, second, { timeout: 30_000 });
  seen.rollbackQuestion = await confirmed(`button.rollback[data-id="${first}"]`);
  await page.waitForFunction((id) => document.getElementById('active').dataset.id === id
    && /Active/.test(document.querySelector(`#history tr[title="${id}"]`)?.textContent || ''), first, { timeout: 30_000 });
  seen.afterRollback = { active: await page.$eval('#active', (e) => e.dataset.id), activeText: await text('active'), first, second, history: await page.$$eval('#history tr', (rows) => rows.map((r) => r.innerText)) };
  await shot(page, '8-rollback');
  // The second calibration, still on screen, was active until the rollback:
  // it says so, and offers no Accept that would undo the rollback.
  await page.waitForFunction(() => /was the active calibration until/.test(document.getElementById('activeline').textContent), null, { timeout: 10_000 });
  seen.replaced = { line: await text('activeline'), acceptHidden: await page.$eval('#accept', (b) => b.hidden) };

  // A third calibration, aborted: "aborting…" once the daemon has the
  // Abort, while the robot halts and walks home, with no time left shown;
  // then "aborted: at home".
  await calibrate();
  // Pressed early in the run (poses 2 to 39 of 52), so that it cannot end
  // before the Abort arrives.
  await page.waitForFunction(() => /pose ([2-9]|[1-3]\d) of \d+/.test(document.getElementById('progress').textContent), null, { timeout: 60_000, polling: 50 });
  seen.abortPressedAt = await text('progress');
  await page.click('#abort');
  await page.waitForFunction(() => ['aborting…', 'aborted: at home'].includes(document.getElementById('progress').textContent), null, { timeout: 10_000 })
    .catch(async (e) => { seen.abortTitles = [await text('progress'), await text('step'), await text('abort-note')]; throw e; });
  seen.aborting = await text('progress');
  seen.abortingTimes = await text('times');
  if (seen.aborting === 'aborting…' && seen.abortingTimes) problems.push(`while aborting the page said ${JSON.stringify(seen.abortingTimes)}`);
  await page.waitForFunction(() => document.getElementById('progress').textContent === 'aborted: at home', null, { timeout: 60_000 });
  seen.aborted = await text('step');
  if (/aborted: aborted/.test(seen.aborted)) problems.push(`the reason repeats itself: ${seen.aborted}`);
  await overflow('aborted');
  await shot(page, '7-aborted');

  // A pad: two columns side by side.
  await page.setViewportSize({ width: 1024, height: 1366 });
  await page.waitForTimeout(300);
  seen.padColumns = await page.$$eval('main > .column', (cols) => cols.map((c) => Math.round(c.getBoundingClientRect().left)));
  await overflow('pad');
  await shot(page, '9-pad');
} catch (error) {
  problems.push(`the browser failed: ${error.stack ?? error}`);
} finally {
  if (browser) await browser.close();
}
console.log(JSON.stringify({ url, seen, problems }));
for (const problem of problems) console.error(`serve.mjs: ${problem}`);
process.exit(problems.length === 0 ? 0 : 1);
