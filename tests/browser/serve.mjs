// Drives the `groundcal serve` terminal page in headless Chromium as an
// operator would on a phone (tests/serve_browser.rs):
//
//   node tests/browser/serve.mjs URL TOKEN SCREENSHOT_DIR
//
// Types the token, presses Calibrate, watches "pose i of N" and the live
// θ/e_d chart fill in, waits for the verdict, presses Accept. Checks: no
// console error, no page error, no request leaving the server (the page works
// offline). Saves serve-1-idle.png,
// serve-2-progress.png, serve-3-verdict.png, serve-4-accepted.png and, after a second
// calibration aborted, serve-7-aborted.png. Prints
// one JSON line of what it saw; exits 0 when every check passes, 1 otherwise,
// 2 on bad usage.

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
  await shot(page, '1-idle');

  await page.fill('#token', token);
  await page.click('#calibrate');
  await page.waitForFunction(() => /pose [1-9]\d* of \d+/.test(document.getElementById('progress').textContent), null, { timeout: 60_000 });
  seen.progress = await page.locator('#progress').innerText();
  seen.robot = await page.locator('#robot').innerText();
  // The live chart: θ and e_d of the provisional solve while poses go by.
  await page.waitForFunction(() => Number(document.getElementById('theta').dataset.points || 0) >= 6
    && document.getElementById('verdict').textContent === '', null, { timeout: 60_000 });
  seen.livePoints = await page.$$eval('#theta circle', (n) => n.length);
  seen.liveProgress = await page.locator('#progress').innerText();
  seen.liveLabel = await page.locator('#theta text').textContent();
  await shot(page, '2-progress');

  await page.waitForFunction(() => ['Accepted', 'Rejected'].includes(document.getElementById('verdict').textContent), null, { timeout: 180_000 });
  seen.verdict = await page.locator('#verdict').innerText();
  seen.points = await page.$$eval('#theta circle', (n) => n.length);
  await shot(page, '3-verdict');

  await page.click('#accept');
  await page.waitForFunction(() => document.getElementById('message').textContent.startsWith('accepted'), null, { timeout: 30_000 });
  seen.message = await page.locator('#message').innerText();
  seen.storedToken = await page.evaluate(() => localStorage.getItem('groundcal-token'));
  const overflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
  if (overflow > 1) problems.push(`the page is ${overflow} px wider than the screen`);
  await shot(page, '4-accepted');

  // A second calibration, aborted: "aborting…" while the robot halts and
  // walks home, then "at home".
  await page.click('#calibrate');
  await page.waitForFunction(() => /pose [2-9]\d* of \d+/.test(document.getElementById('progress').textContent), null, { timeout: 60_000 });
  await page.click('#abort');
  seen.aborting = await page.locator('#progress').innerText();
  if (seen.aborting !== 'aborting…') problems.push(`after Abort the page said ${JSON.stringify(seen.aborting)}`);
  await page.waitForFunction(() => document.getElementById('progress').textContent === 'at home', null, { timeout: 60_000 });
  seen.aborted = await page.locator('#robot').innerText();
  if (/aborted: aborted/.test(seen.aborted)) problems.push(`the reason repeats itself: ${seen.aborted}`);
  await shot(page, '7-aborted');
} catch (error) {
  problems.push(`the browser failed: ${error.stack ?? error}`);
} finally {
  if (browser) await browser.close();
}
console.log(JSON.stringify({ url, seen, problems }));
for (const problem of problems) console.error(`serve.mjs: ${problem}`);
process.exit(problems.length === 0 ? 0 : 1);
