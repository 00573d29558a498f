// The terminal page when the daemon dies mid-run, in headless Chromium at
// phone size (tests/serve_browser.rs):
//
//   node tests/browser/serve-lost.mjs URL TOKEN SCREENSHOT_DIR PID RESTART_JSON
//
// Presses Calibrate (and confirms), waits for pose 3, kills the daemon
// (SIGKILL, PID), and measures how long the page takes to say that contact
// is lost; Abort then says that it could not be sent; then starts
// the daemon again (RESTART_JSON: the command as a JSON array) and waits for
// the page to find it and show the run as interrupted. Saves
// serve-5-lost.png and serve-6-interrupted.png. Prints one JSON line of what
// it saw (with the restarted daemon's pid); exits 0 when every check passes.

import { spawn } from 'node:child_process';
import { resolve } from 'node:path';

import { deadline, launch } from './chromium.mjs';

const [url, token, shotDir, pid, restartJson] = process.argv.slice(2);
if (!url || !token || !shotDir || !pid || !restartJson) {
  console.error('usage: node serve-lost.mjs URL TOKEN SCREENSHOT_DIR PID RESTART_JSON');
  process.exit(2);
}
deadline('serve-lost.mjs', 180);

const problems = [];
const seen = {};
const shot = (page, name) => page.screenshot({ path: resolve(shotDir, `serve-${name}.png`), fullPage: true });
let browser;
try {
  browser = await launch({ viewport: { width: 390, height: 844 }, isMobile: true, hasTouch: true, deviceScaleFactor: 2 });
  const page = browser.context.pages()[0] ?? (await browser.context.newPage());
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  await page.goto(url, { waitUntil: 'load', timeout: 30_000 });
  await page.fill('#token', token);
  await page.click('#calibrate');
  await page.waitForSelector('#confirm-run:not([hidden])');
  await page.click('#confirm-run-yes');
  await page.waitForFunction(() => /pose ([3-9]|\d\d+) of \d+/.test(document.getElementById('progress').textContent), null, { timeout: 60_000 });

  const killed = Date.now();
  process.kill(Number(pid), 'SIGKILL');
  await page.waitForFunction(() => !document.getElementById('lost').hidden, null, { timeout: 10_000 });
  seen.lostAfterMs = Date.now() - killed;
  seen.banner = await page.locator('#lost').innerText();
  seen.buttonsDisabled = await page.evaluate(() => ['calibrate', 'check', 'accept'].every((id) => document.getElementById(id).disabled));
  // Abort stays pressable (the run may still go on) and says it did not get through.
  await page.click('#abort');
  await page.waitForFunction(() => /could not be sent/.test(document.getElementById('abort-note').textContent), null, { timeout: 10_000 });
  seen.abortMessage = await page.locator('#abort-note').innerText();
  await page.waitForTimeout(1200);
  await shot(page, '5-lost');
  if (seen.lostAfterMs > 3000) problems.push(`the page said contact was lost only after ${seen.lostAfterMs} ms`);
  if (!seen.buttonsDisabled) problems.push('Calibrate, Check or Accept stayed enabled with no contact');

  const [program, ...args] = JSON.parse(restartJson);
  const daemon = spawn(program, args, { detached: true, stdio: 'ignore' });
  daemon.unref();
  seen.restartedPid = daemon.pid;
  await page.waitForFunction(() => document.getElementById('lost').hidden
    && document.getElementById('verdict').textContent === 'Interrupted', null, { timeout: 60_000 });
  seen.verdict = await page.locator('#verdict').innerText();
  seen.reason = await page.locator('#reasons').innerText();
  await shot(page, '6-interrupted');
} catch (error) {
  problems.push(`the browser failed: ${error.stack ?? error}`);
} finally {
  if (browser) await browser.close();
}
console.log(JSON.stringify({ url, seen, problems }));
for (const problem of problems) console.error(`serve-lost.mjs: ${problem}`);
process.exit(problems.length === 0 ? 0 : 1);
