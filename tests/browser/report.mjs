// Opens a groundcal report in headless Chromium, as a person would on a phone
// and on a laptop, and checks what they would see (tests/report_browser.rs).
//
//   node tests/browser/report.mjs REPORT.html SCREENSHOT.png
//
// Checks: no console error, no page error, no request leaving file:// (the
// report must work with no network), the verdict shown, at least four charts
// rendered with a size, every section an operator needs there with content or
// a reason why not (quality gates with pass or fail, the setup, the weakest
// directions in words, the correlations heat map of 36 cells, the signed
// residuals, the commanded poses), and nothing wider than the screen on a
// phone: not the page, and no element outside a table's own scrolling box
// (with every <details> opened). Saves full-page screenshots, details open:
// SCREENSHOT.png (phone, 390×844) and SCREENSHOT-desktop.png (1280×900).
// Prints one JSON line of what it saw on stdout (each section's rows, for the
// Rust test to compare with the result); exits 0 when every check passes, 1
// when one fails, 2 on bad usage.

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
    if (!['Passed its checks', 'Failed its checks'].includes(verdict)) {
      problems.push(`${name}: no verdict shown (found "${verdict}")`);
    } else if (!(await verdictLocator.isVisible())) {
      problems.push(`${name}: the verdict is not visible`);
    } else {
      // Visible to the DOM is not readable: the words must not be the
      // colour of what they stand on.
      const [color, background] = await page.$eval('#verdict', (e) => [getComputedStyle(e).color, getComputedStyle(e).backgroundColor]);
      if (color === background || background === 'rgb(255, 255, 255)' || background === 'rgba(0, 0, 0, 0)') {
        problems.push(`${name}: the verdict's words (${color}) stand on ${background}`);
      }
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

    // What <details> hide must fit too, and be seen in the screenshot.
    await page.evaluate(() => {
      for (const d of document.querySelectorAll('details')) d.open = true;
    });

    // Wide tables scroll inside their own box; the page itself must not.
    const overflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
    if (overflow > 1) problems.push(`${name}: the page is ${overflow} px wider than the screen`);
    // Nor may anything stick out of the screen, except inside a scrolling box.
    const sticking = await page.evaluate(() => {
      const width = document.documentElement.clientWidth;
      const out = [];
      for (const el of document.querySelectorAll('main *')) {
        const box = el.closest('.scroll');
        if ((box && box !== el) || el.closest('svg') !== null && el.tagName.toLowerCase() !== 'svg') continue;
        const r = el.getBoundingClientRect();
        if (r.width > 0 && (r.right > width + 1 || r.left < -1)) {
          out.push(`${el.tagName.toLowerCase()}${el.id ? '#' + el.id : ''}${el.className && typeof el.className === 'string' ? '.' + el.className.split(' ').join('.') : ''} (${Math.round(r.left)}..${Math.round(r.right)} of ${width})`);
        }
      }
      return out;
    });
    for (const what of sticking.slice(0, 5)) problems.push(`${name}: sticks out of the screen: ${what}`);
    // The tables an operator reads must fit whole, even on a phone; only the
    // table of every pose and the matrix may scroll in their box.
    const cramped = await page.evaluate(() =>
      [...document.querySelectorAll('table.gates, table.params, table.nominal, table.heat, table.residuals, table.commanded')]
        .filter((t) => t.getBoundingClientRect().width > t.parentElement.clientWidth + 1)
        .map((t) => `table.${t.className} (${Math.round(t.getBoundingClientRect().width)} px in ${t.parentElement.clientWidth} px)`),
    );
    for (const what of cramped) problems.push(`${name}: needs sideways scrolling: ${what}`);

    const sections = await page.evaluate(() => {
      const text = (el) => (el ? el.textContent.replace(/\s+/g, ' ').trim() : '');
      const all = (selector) => [...document.querySelectorAll(selector)];
      const cells = (tr) => [...tr.cells].map(text);
      const present = (id) => {
        const section = document.getElementById(id);
        return {
          present: section !== null && text(section.querySelector('h2')) !== '',
          none: text(section?.querySelector(':scope > .none')),
        };
      };
      return {
        gates: {
          ...present('gates'),
          rows: all('#gates table.gates tbody tr').map((tr) => ({
            gate: tr.dataset.gate,
            passed: tr.classList.contains('pass'),
            cells: cells(tr),
          })),
        },
        correlations: {
          ...present('correlations'),
          columns: all('#correlations table.heat thead th').map(text).filter((t) => t !== ''),
          rows: all('#correlations table.heat tbody th').map(text),
          cells: all('#correlations table.heat td.cell').map((td) => ({
            text: text(td),
            background: getComputedStyle(td).backgroundColor,
            width: td.getBoundingClientRect().width,
          })),
        },
        observability: {
          ...present('observability'),
          weakest: all('#observability .weakest li').map((li) => ({
            kind: li.dataset.kind,
            direction: text(li.querySelector('.direction')),
            text: text(li),
          })),
        },
        setup: {
          ...present('setup'),
          facts: Object.fromEntries(all('#setup dl.setup dt').map((dt) => [text(dt), text(dt.nextElementSibling)])),
          nominal: all('#setup table.nominal tbody tr').map(cells),
          notes: all('#setup .none').map(text),
        },
        accuracy: {
          ...present('accuracy'),
          gateLabels: all('#accuracy svg text').map(text).filter((t) => t.startsWith('gate ')),
          notes: all('#accuracy .chart-note').map(text),
        },
        residuals: {
          ...present('residuals'),
          rows: all('#residuals table.residuals tbody tr').map((tr) => ({
            used: !tr.classList.contains('unused'),
            cells: cells(tr),
          })),
        },
        planes: {
          ...present('planes'),
          legend: all('#planes .legend li').map(text),
          squares: all('#planes svg rect').length,
        },
        commanded: {
          ...present('commanded'),
          rows: all('#commanded table.commanded tbody tr').map(cells),
          svgs: all('#commanded svg').length,
        },
      };
    });
    for (const [id, section] of Object.entries(sections)) {
      if (!section.present) problems.push(`${name}: no section #${id} with a heading`);
    }
    const either = (id, has, what) => {
      if (!has && sections[id].none === '') problems.push(`${name}: #${id} has no ${what} and does not say why`);
    };
    either('gates', sections.gates.rows.length > 0, 'gate rows');
    for (const row of sections.gates.rows) {
      const verdict = row.cells[3] ?? '';
      if (row.cells.length !== 4 || !(row.passed ? /pass/.test(verdict) : /FAIL/.test(verdict))) {
        problems.push(`${name}: gate row ${JSON.stringify(row)} is not gate, limit, measured, pass/fail`);
      }
    }
    either('correlations', sections.correlations.cells.length > 0, 'heat map');
    if (sections.correlations.cells.length > 0) {
      const { cells, columns, rows } = sections.correlations;
      const labels = ['α', 'β', 'γ', 'px', 'py', 'pz'];
      if (cells.length !== 36) problems.push(`${name}: the heat map has ${cells.length} cells, not 36`);
      if (JSON.stringify(columns) !== JSON.stringify(labels) || JSON.stringify(rows) !== JSON.stringify(labels)) {
        problems.push(`${name}: the heat map is labelled ${JSON.stringify(columns)} × ${JSON.stringify(rows)}`);
      }
      if (cells.some((c) => !/^(-?\d\.\d\d|1|—)$/.test(c.text))) problems.push(`${name}: a heat map cell has no value: ${JSON.stringify(cells)}`);
      if (new Set(cells.map((c) => c.background)).size < 3) problems.push(`${name}: the heat map's cells are not coloured by |r|`);
      if (cells.some((c) => c.width < 30)) problems.push(`${name}: heat map cells narrower than 30 px`);
    }
    either('observability', sections.observability.weakest.length > 0, 'weakest directions');
    for (const w of sections.observability.weakest) {
      if (w.direction === '') problems.push(`${name}: the weakest ${w.kind} is not named`);
    }
    either('residuals', sections.residuals.rows.length > 0, 'residuals');
    either('commanded', sections.commanded.rows.length > 0, 'commanded poses');
    if (sections.setup.facts.input === undefined) problems.push(`${name}: the setup does not name the input`);

    // The depth image's own warp, when the result has a pattern: the
    // picture's cells as the browser decoded them (RGB), to compare with
    // the result it was drawn from.
    const pattern = await page.evaluate(() => {
      const section = document.getElementById('depth-pattern');
      if (!section) return null;
      const text = (el) => (el ? el.textContent.replace(/\s+/g, ' ').trim() : '');
      const img = section.querySelector('img.warp');
      let picture = null;
      if (img) {
        const canvas = document.createElement('canvas');
        canvas.width = img.naturalWidth; canvas.height = img.naturalHeight;
        const context = canvas.getContext('2d');
        context.drawImage(img, 0, 0);
        const data = context.getImageData(0, 0, canvas.width, canvas.height).data;
        // Six hex digits per cell (a long array would not fit the pipe).
        let rgb = '';
        const hex = (v) => v.toString(16).padStart(2, '0');
        for (let i = 0; i < data.length; i += 4) rgb += hex(data[i]) + hex(data[i + 1]) + hex(data[i + 2]);
        const box = img.getBoundingClientRect();
        picture = { naturalWidth: img.naturalWidth, naturalHeight: img.naturalHeight, width: box.width, height: box.height, rgb };
      }
      return {
        heading: text(section.querySelector('h2')),
        words: text(section.querySelector('.warp-words')),
        none: text(section.querySelector('.none')),
        ticks: [...section.querySelectorAll('.warp-ticks span')].map(text),
        picture,
      };
    });

    const screenshot = screenshotFor(name);
    await page.screenshot({ path: screenshot, fullPage: true });
    const bytes = statSync(screenshot).size;
    if (bytes === 0) problems.push(`${name}: the screenshot ${screenshot} is empty`);

    return { seen: { viewport: name, verdict, svgs: svgs.length, rendered, overflow, sticking, sections, pattern, screenshot, bytes }, problems };

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
for (const problem of problems) console.error(`report.mjs: ${problem}`);
// Exit once the whole document is out: a pipe takes 64 KiB at a time, and
// process.exit does not wait for the rest.
process.stdout.write(JSON.stringify({ url, seen, problems }) + '\n', () => process.exit(problems.length === 0 ? 0 : 1));
