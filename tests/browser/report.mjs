// Opens a groundcal report in headless Chromium, as a person would on a phone
// and on a laptop, and checks what they would see (tests/report_browser.rs).
//
//   node tests/browser/report.mjs REPORT.html SCREENSHOT.png
//
// Checks: no console error, no page error, no request leaving file:// (the
// report must work with no network), the verdict shown, at least four charts
// rendered with a size, and no horizontal overflow of the page on a phone.
// Saves full-page screenshots: SCREENSHOT.png (phone, 390×844) and
// SCREENSHOT-desktop.png (1280×900). Prints one JSON line of what it saw on
// stdout; exits 0 when every check passes, 1 when one fails, 2 on bad usage.

import { statSync } from 'node:fs';
import { resolve } from 'node:path';
import { pathToFileURL } from 'node:url';

import { deadline, launch } from './chromium.mjs';

const VIEWPORTS = [
  { name: 'phone', viewport: { width: 390, height: 844 }, isMobile: true, hasTouch: true, deviceScaleFactor: 2 },
  { name: 'desktop', viewport: { width: 1280, height: 900 }, isMobile: false, hasTouch: false, deviceScaleFactor: 1 },
];

const [htmlArg, pngArg] = process.argv.slice(2);
if (!htmlArg || !pngArg) {
  console.error('usage: node report.mjs REPORT.html SCREENSHOT.png');
  process.exit(2);
}
const url = pathToFileURL(resolve(htmlArg)).href;
const screenshotFor = (name) => (name === 'phone' ? resolve(pngArg) : resolve(pngArg).replace(/(\.png)?$/, `-${name}.png`));

deadline('report.mjs', 120);

/** Opens the report in one viewport and returns what was seen and what went wrong. */
async function visit({ name, ...options }) {
  const problems = [];
  const { context, close } = await launch(options);
  try {
    await context.route('**/*', (route) => {
      const requested = route.request().url();
      if (requested.startsWith('file:') || requested.startsWith('data:')) {
        return route.continue();
      }
      problems.push(`${name}: the page requested ${requested}`);
      return route.abort();
    });
    const page = context.pages()[0] ?? (await context.newPage());
    page.on('console', (message) => {
      if (message.type() === 'error') problems.push(`${name}: console error: ${message.text()}`);
    });
    page.on('pageerror', (error) => problems.push(`${name}: page error: ${error.message}`));

    await page.goto(url, { waitUntil: 'load', timeout: 30_000 });

    const verdictLocator = page.locator('#verdict h1');
    const verdict = (await verdictLocator.count()) ? (await verdictLocator.innerText()).trim() : '';
    if (!['ACCEPTED', 'REJECTED'].includes(verdict)) {
      problems.push(`${name}: no verdict shown (found "${verdict}")`);
    } else if (!(await verdictLocator.isVisible())) {
      problems.push(`${name}: the verdict is not visible`);
    }

    const svgs = await page.$$eval('svg', (nodes) =>
      nodes.map((n) => {
        const box = n.getBoundingClientRect();
        return { width: box.width, height: box.height };
      }),
    );
    const rendered = svgs.filter((box) => box.width > 0 && box.height > 0).length;
    if (rendered < 4) {
      problems.push(`${name}: ${rendered} charts rendered with a size, expected at least 4 (${JSON.stringify(svgs)})`);
    }

    // Wide tables scroll inside their own box; the page itself must not.
    const overflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
    if (overflow > 1) problems.push(`${name}: the page is ${overflow} px wider than the screen`);

    const screenshot = screenshotFor(name);
    await page.screenshot({ path: screenshot, fullPage: true });
    const bytes = statSync(screenshot).size;
    if (bytes === 0) problems.push(`${name}: the screenshot ${screenshot} is empty`);

    return { seen: { viewport: name, verdict, svgs: svgs.length, rendered, overflow, screenshot, bytes }, problems };
  } finally {
    await close();
  }
}

const seen = [];
const problems = [];
try {
  for (const viewport of VIEWPORTS) {
    const visited = await visit(viewport);
    seen.push(visited.seen);
    problems.push(...visited.problems);
  }
} catch (error) {
  problems.push(`the browser failed: ${error.stack ?? error}`);
}
console.log(JSON.stringify({ url, seen, problems }));
for (const problem of problems) console.error(`report.mjs: ${problem}`);
process.exit(problems.length === 0 ? 0 : 1);
