// The terminal page of a `groundcal serve` whose sensor was knocked since
// its active calibration (tests/serve_browser.rs):
//
//   node tests/browser/serve-check.mjs URL TOKEN SCREENSHOT_DIR
//
// At phone size: waits for the check the service makes at start to show the
// drift banner and the check's figures beside the active calibration; then
// types the token and presses Check (and confirms), and waits for a second
// check's outcome. Then calibrates again and accepts: the drift banner,
// which spoke of the previous calibration, must go.
// Checks: no console error, no page error, no page wider than the screen.
// Saves serve-10-drift.png, serve-11-checked.png and serve-15-recalibrated.png. Prints one JSON line of
// what it saw; exits 0 when every check passes, 1 otherwise, 2 on bad usage.

import { resolve } from 'node:path';

import { deadline, launch } from './chromium.mjs';

const [url, token, shotDir] = process.argv.slice(2);
if (!url || !token || !shotDir) {
  console.error('usage: node serve-check.mjs URL TOKEN SCREENSHOT_DIR');
  process.exit(2);
}
deadline('serve-check.mjs', 120);

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
  const page = browser.context.pages()[0] ?? (await browser.context.newPage());
  page.on('console', (m) => {
    if (m.type() === 'error') problems.push(`console error: ${m.text()}`);
  });
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  const text = (id) => page.locator('#' + id).innerText();
  const overflow = async (where) => {
    const wider = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
    if (wider > 1) problems.push(`${where}: the page is ${wider} px wider than the screen`);
  };

  await page.goto(url, { waitUntil: 'load', timeout: 30_000 });
  await page.waitForSelector('#drift:not([hidden])', { timeout: 60_000 });
  await page.waitForFunction(() => document.querySelectorAll('#checks li').length > 0);
  seen.banner = await text('drift');
  seen.checkline = await text('checkline');
  seen.checks = await page.$$eval('#checks li', (n) => n.map((e) => e.textContent));
  seen.checkEnabled = !(await page.$eval('#check', (b) => b.disabled));
  await overflow('drift');
  await shot(page, '10-drift');

  const before = await page.evaluate(async () => (await (await fetch('/api/status')).json()).check.finished);
  if (!await page.$eval('#token-card', (d) => d.open)) await page.click('#token-card summary');
  await page.fill('#token', token);
  await page.click('#check');
  await page.waitForSelector('#confirm-run:not([hidden])');
  seen.confirmCheck = await text('confirm-run-text');
  await page.click('#confirm-run-yes');
  await page.waitForFunction(async (previous) => {
    const check = (await (await fetch('/api/status')).json()).check;
    return check && check.finished && check.finished !== previous && check.by.includes('terminal page');
  }, before, { timeout: 60_000, polling: 250 });
  await page.waitForFunction(() => /terminal page/.test(document.getElementById('checkline').textContent));
  seen.secondCheckline = await text('checkline');
  seen.secondBanner = await text('drift');
  seen.message = await text('message');
  await overflow('checked');
  await shot(page, '11-checked');

  // Recalibrate the knocked sensor and make the result active: the banner
  // spoke of the previous calibration, and goes.
  await page.click('#calibrate');
  await page.waitForSelector('#confirm-run:not([hidden])');
  await page.click('#confirm-run-yes');
  await page.waitForFunction(() => document.getElementById('verdict').textContent === 'Passed its checks'
    && !document.getElementById('result').hidden, null, { timeout: 120_000 });
  seen.bannerBeforeAccept = !(await page.$eval('#drift', (e) => e.hidden));
  await page.click('#accept');
  await page.waitForSelector('#confirm:not([hidden])');
  const accepted = Date.now();
  await page.click('#confirm-yes');
  await page.waitForFunction(() => document.getElementById('drift').hidden, null, { timeout: 10_000, polling: 50 });
  seen.bannerGoneAfterMs = Date.now() - accepted;
  seen.checklineAfterAccept = await text('checkline');
  await overflow('recalibrated');
  await shot(page, '15-recalibrated');
} catch (error) {
  problems.push(`the browser failed: ${error.stack ?? error}`);
} finally {
  if (browser) await browser.close();
}
console.log(JSON.stringify({ url, seen, problems }));
for (const problem of problems) console.error(`serve-check.mjs: ${problem}`);
process.exit(problems.length === 0 ? 0 : 1);
