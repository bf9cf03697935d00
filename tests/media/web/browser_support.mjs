// Test support for the browser tests of the web view (browser_live_test.mjs,
// browser_view_test.mjs) and the live-view benchmark (tests/bench/web_attach.mjs): the
// command line, the ok/FAIL report, `omnitwin` as a child whose "web view: URL" line is
// awaited, headless Chromium through puppeteer-core (Debian's chromium, software WebGL) with
// page and console errors collected, and a clean end (browser and child never left behind).
import { spawn } from 'node:child_process';

const PUPPETEER = new URL('../../../media/web/node_modules/puppeteer-core/lib/esm/puppeteer/puppeteer-core.js', import.meta.url);

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

export function withTimeout(promise, ms, what) {
  let timer;
  return Promise.race([promise, new Promise((_, rej) => { timer = setTimeout(() => rej(new Error(`timed out after ${ms / 1000} s: ${what}`)), ms); })])
    .finally(() => clearTimeout(timer));
}

// Headless Chromium at 1280×800; `errors` collects page errors and console errors.
export async function launchBrowser(log = () => {}) {
  const { default: puppeteer } = await import(PUPPETEER.href);
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
  });
  const page = await browser.newPage();
  await page.setViewport({ width: 1280, height: 800 });
  const errors = [];
  page.on('pageerror', (err) => { errors.push(`pageerror: ${err.message}`); log(`page error: ${err.message}`); });
  page.on('console', (msg) => {
    const where = msg.location() && msg.location().url ? ` [${msg.location().url}]` : '';
    if (msg.type() === 'error') { errors.push(`console error: ${msg.text()}${where}`); log(`console error: ${msg.text()}${where}`); }
    else if (msg.type() === 'warn' || msg.type() === 'warning') log(`console warning: ${msg.text()}`);
  });
  return { browser, page, errors };
}

// One test's harness: `--key value` arguments (after `--`: extra), `required` keys checked,
// `--timeout` (default `timeoutS`) for the whole test.
export function harness(name, usageLine, required, timeoutDefaultS) {
  const usage = (msg) => {
    if (msg) console.error(`${name}: ${msg}`);
    console.error(`usage: ${usageLine}`);
    process.exit(2);
  };
  const opts = {};
  const extra = [];
  const argv = process.argv.slice(2);
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    if (a === '--') { extra.push(...argv.slice(i + 1)); break; }
    if (!a.startsWith('--') || i + 1 >= argv.length) usage(`bad argument: ${a}`);
    opts[a.slice(2)] = argv[++i];
  }
  for (const k of required) if (!opts[k]) usage(`--${k} is required`);
  const timeoutS = Number(opts.timeout || timeoutDefaultS);
  if (!(timeoutS > 0)) usage('--timeout must be a positive number of seconds');

  const t0 = Date.now();
  const log = (...a) => console.log(`[${name} ${((Date.now() - t0) / 1000).toFixed(2)}s]`, ...a);
  const h = { opts, extra, timeoutS, log, failures: 0, warnings: 0, child: null, childExit: null, browser: null };
  const childOutput = [];
  h.check = (cond, what, detail = '') => {
    log(`${cond ? 'ok  ' : 'FAIL'}  ${what}${detail ? ` (${detail})` : ''}`);
    if (!cond) h.failures++;
    return !!cond;
  };
  h.must = (cond, what, detail) => { if (!h.check(cond, what, detail)) throw new Error(`cannot go on: ${what}`); };
  h.warn = (what) => { h.warnings++; log(`WARN  ${what}`); };

  const killChild = (signal = 'SIGKILL') => {
    const c = h.child;
    if (c && c.exitCode === null && c.signalCode === null) { try { c.kill(signal); } catch { /* gone */ } }
  };
  const killBrowser = () => {
    const p = h.browser && h.browser.process();
    if (p && p.exitCode === null) { try { p.kill('SIGKILL'); } catch { /* gone */ } }
  };
  const dumpChild = () => {
    if (childOutput.length) console.log(`---- omnitwin output (last lines) ----\n${childOutput.slice(-60).join('\n')}\n----`);
  };
  process.on('exit', () => { killChild(); killBrowser(); });
  for (const sig of ['SIGINT', 'SIGTERM']) process.on(sig, () => { log(`${sig}: stopping`); process.exit(1); });
  const overall = setTimeout(() => {
    log(`FAIL  the whole test took longer than --timeout ${timeoutS} s`);
    dumpChild();
    process.exit(1);
  }, timeoutS * 1000);

  // `opts.omnitwin ARGS…` with its output kept; resolves to the URL of its "web view:" line.
  h.startOmnitwin = (args) => {
    log(`starting: ${opts.omnitwin} ${args.join(' ')}`);
    const child = spawn(opts.omnitwin, args, { stdio: ['ignore', 'pipe', 'pipe'] });
    h.child = child;
    h.childExit = new Promise((resolve) => {
      child.on('error', (err) => { childOutput.push(`(spawn error: ${err.message})`); resolve({ code: null, signal: null, error: err }); });
      child.on('exit', (code, signal) => resolve({ code, signal }));
    });
    let url = null;
    const urlPromise = new Promise((resolve, reject) => {
      const onLine = (stream) => {
        let buf = '';
        return (chunk) => {
          buf += chunk.toString();
          let nl;
          while ((nl = buf.indexOf('\n')) >= 0) {
            const line = buf.slice(0, nl).replace(/\r$/, '');
            buf = buf.slice(nl + 1);
            childOutput.push(`${stream}: ${line}`);
            if (childOutput.length > 400) childOutput.splice(0, 100);
            const m = /web view: (https?:\/\/\S+)/.exec(line);
            if (m && !url) { url = m[1]; resolve(url); }
          }
        };
      };
      child.stdout.on('data', onLine('stdout'));
      child.stderr.on('data', onLine('stderr'));
      h.childExit.then((e) => { if (!url) reject(new Error(`omnitwin ended before printing "web view: URL" (exit ${e.code}, signal ${e.signal}${e.error ? `, ${e.error.message}` : ''})`)); });
    });
    return withTimeout(urlPromise, 60000, 'the "web view: URL" line of omnitwin');
  };

  h.launchBrowser = async () => {
    const b = await launchBrowser(log);
    h.browser = b.browser;
    return b;
  };

  // Runs the test body, then closes the browser, ends the child and exits 0 (passed) or 1.
  h.run = async (main) => {
    try {
      await main();
    } catch (err) {
      h.failures++;
      log(`FAIL  ${err && err.stack ? err.stack : err}`);
    } finally {
      clearTimeout(overall);
      if (h.browser) await h.browser.close().catch(() => {});
      killBrowser();
      if (h.child && h.child.exitCode === null && h.child.signalCode === null) {
        killChild('SIGTERM');
        await Promise.race([h.childExit, sleep(3000)]);
        killChild('SIGKILL');
      }
      if (h.failures) dumpChild();
      log(h.failures ? `FAILED (${h.failures} failed, ${h.warnings} warnings)` : `PASSED (${h.warnings} warnings)`);
    }
    process.exit(h.failures ? 1 : 0);
  };
  return h;
}
