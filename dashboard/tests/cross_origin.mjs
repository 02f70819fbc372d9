// Issue 35: other web pages cannot use facecapd, and the dashboard works after a login
// from a stage address. facecapd on the sim; Debian's chromium, headless (playwright-core).
//  1. Loopback without a token (the documented quick setup): a page served from another
//     origin (a second HTTP server, another port) tries what the review did, a no-cors
//     text/plain POST /record/start, a CORS JSON POST, a text/plain form POST, and a
//     WebSocket to /stream, then the same against /record/stop of a running take.
//  2. With a token at ADDRESS (default 127.0.0.1; 10.77.0.1 inside `unshare -rn`, see
//     tests/CMakeLists.txt): the dashboard sends the browser to its login page, a wrong
//     token is refused on the page, the right one shows the live face and records a take;
//     with that session cookie in the browser the attacking page still cannot start or
//     stop a take nor read the stream; a viewer's login cannot record; DNS rebinding (a
//     name mapped to ADDRESS) gets 421; logout ends the session.
//  With `tls` (third argument): part 2 over HTTPS and WSS (control.http.tls), facecapd
//  making its certificate at start; chromium trusts exactly that key (its public key pin
//  from the log), this script's requests exactly that certificate, and the cookie is Secure.
// Every verdict is checked from facecapd's side: its takes directory and /status.
// Usage: node dashboard/tests/cross_origin.mjs <build dir> [ADDRESS] [tls]; exits 77 when
// chromium or the built dashboard is absent.
import { spawn } from 'node:child_process';
import { chmodSync, existsSync, mkdirSync, mkdtempSync, readdirSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { createServer, request as httpRequest } from 'node:http';
import { request as httpsRequest } from 'node:https';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { launchChromium, missingBrowser } from './chromium.mjs';

const kSkipped = 77;
const build = resolve(process.argv[2] ?? 'build');
const address = process.argv[3] ?? '127.0.0.1';
const tls = process.argv[4] === 'tls';
const scheme = tls ? 'https' : 'http';
if (missingBrowser()) {
  console.log(`SKIPPED: ${missingBrowser()}`);
  process.exit(kSkipped);
}
if (!existsSync(join(build, 'dashboard', 'www', 'login.html'))) {
  console.log(`SKIPPED: the dashboard is not built in ${join(build, 'dashboard', 'www')}`);
  process.exit(kSkipped);
}
const facecapd = join(build, 'daemon', 'facecapd');
const shots = join(build, 'dashboard-test');
mkdirSync(shots, { recursive: true });

let passed = 0, failed = 0;
function check(what, ok, detail = '') {
  if (ok) passed += 1;
  else failed += 1;
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}${detail ? `: ${detail}` : ''}`);
  return ok;
}

const work = mkdtempSync(join(tmpdir(), 'facecap-cross-origin-'));
const kOperatorToken = 'operator-token-7f3a9c';
const kViewerToken = 'viewer-token-21be04';
writeFileSync(join(work, 'token'), `${kOperatorToken}\n`);
writeFileSync(join(work, 'viewer-token'), `${kViewerToken}\n`);
chmodSync(join(work, 'token'), 0o600);
chmodSync(join(work, 'viewer-token'), 0o600);

// facecapd on the sim at ADDRESS, a free port; resolves to { child, port, log() }.
function startDaemon(name, settings) {
  const takes = join(work, name);
  mkdirSync(takes);
  const child = spawn(facecapd, [
    '--set', 'control.http.enabled=true', '--set', `control.http.address=${address}`, '--set', 'control.http.port=0',
    '--set', `outputs.shm.name=facecap-cross-origin-${process.pid}-${name}`,
    '--set', `outputs.recording.directory=${takes}`, '--set', 'control.status_interval_s=0.25',
    '--set', 'control.run_seconds=300', ...settings.flatMap((s) => ['--set', s]),
    ...(tls ? ['--set', 'control.http.tls=true', '--set', `control.http.tls_certificate=${join(takes, 'tls', 'facecapd.crt')}`,
               '--set', `control.http.tls_key=${join(takes, 'tls', 'facecapd.key')}`] : []),
  ], { env: { ...process.env, FACECAPD_ALLOW_ROOT: '1' }, stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  child.stdout.on('data', (c) => (log += c));
  child.stderr.on('data', (c) => (log += c));
  return new Promise((resolvePort, reject) => {
    const timer = setInterval(() => {
      const port = /control API on https?:\/\/[^:]+:(\d+)/.exec(log)?.[1];
      if (port && log.includes('ready: first frame solved')) {
        clearInterval(timer);
        const pin = /public key pin sha256\/\/([A-Za-z0-9+/=]+)/.exec(log)?.[1];
        const ca = tls ? readFileSync(join(takes, 'tls', 'facecapd.crt')) : undefined;
        resolvePort({ child, port: Number(port), takes, pin, ca, log: () => log });
      }
    }, 100);
    child.on('exit', (code) => {
      clearInterval(timer);
      reject(new Error(`facecapd exited (${code}) before it was ready:\n${log}`));
    });
    setTimeout(() => reject(new Error(`facecapd not ready within 60 s:\n${log}`)), 60000);
  });
}

// A request to `daemon` as a script sends it (no Origin), over HTTPS trusting only its
// certificate when the API serves TLS: { status, body (JSON or null) }.
function send(daemon, path, { method = 'GET', headers = {}, body } = {}) {
  return new Promise((done, fail) => {
    const options = { host: address, port: daemon.port, path, method, headers, ca: daemon.ca };
    const r = (tls ? httpsRequest : httpRequest)(options, (response) => {
      let text = '';
      response.on('data', (c) => (text += c));
      response.on('end', () => {
        let json = null;
        try { json = JSON.parse(text); } catch { /* not JSON */ }
        done({ status: response.statusCode, body: json });
      });
    });
    r.on('error', fail);
    r.end(body);
  });
}

// The API as a script: with the operator's token when there is one.
function api(daemon, path, body, token) {
  const headers = token ? { Authorization: `Bearer ${token}` } : {};
  if (body === undefined) return send(daemon, path, { headers });
  headers['Content-Type'] = 'application/json';
  return send(daemon, path, { method: 'POST', headers, body: JSON.stringify(body) });
}
const takesIn = (daemon) => readdirSync(daemon.takes).filter((f) => f.endsWith('.fcrec'));

// The attacking page's server: another origin (another port on loopback).
const attacker = createServer((request, response) => {
  response.writeHead(200, { 'Content-Type': 'text/html' });
  response.end('<!doctype html><title>attacker</title><iframe name="sink"></iframe>');
});
await new Promise((r) => attacker.listen(0, '127.0.0.1', r));
const attackerUrl = `http://127.0.0.1:${attacker.address().port}/`;

// Run in the attacking page: every way a page can reach another origin's API.
async function attack(target) {
  const result = {};
  const send = async (name, path, init) => {
    try {
      const r = await fetch(target + path, init);
      result[name] = r.type === 'opaque' ? 'opaque' : r.status;
    } catch (e) {
      result[name] = 'blocked';
    }
  };
  await send('no_cors_text', '/record/start', { method: 'POST', mode: 'no-cors', credentials: 'include',
    headers: { 'Content-Type': 'text/plain' }, body: JSON.stringify({ take: 'csrf-nocors' }) });
  await send('cors_json', '/record/start', { method: 'POST', credentials: 'include',
    headers: { 'Content-Type': 'application/json' }, body: JSON.stringify({ take: 'csrf-cors' }) });
  await send('cors_read', '/status', { credentials: 'include' });
  await send('no_cors_stop', '/record/stop', { method: 'POST', mode: 'no-cors', credentials: 'include',
    headers: { 'Content-Type': 'text/plain' }, body: '{}' });
  const form = document.createElement('form');
  form.method = 'POST';
  form.enctype = 'text/plain';
  form.target = 'sink';
  form.action = `${target}/record/start`;
  const field = document.createElement('input');
  field.name = '{"take": "csrf-form", "x": "';
  field.value = '"}';
  form.append(field);
  document.body.append(form);
  form.submit();
  await new Promise((r) => setTimeout(r, 1000));
  result.stream = await new Promise((done) => {
    let opened = false, messages = 0;
    const ws = new WebSocket(`${target.replace(/^http/, 'ws')}/stream?rate=30`);
    ws.onopen = () => (opened = true);
    ws.onmessage = () => (messages += 1);
    const finish = () => done({ opened, messages });
    ws.onclose = finish;
    setTimeout(() => { ws.close(); finish(); }, 3000);
  });
  return result;
}

// The attack from a page of another origin against `daemon`; checks facecapd saw nothing.
async function attackAndCheck(context, daemon, token, label) {
  const page = await context.newPage();
  await page.goto(attackerUrl);
  const before = takesIn(daemon);
  const result = await page.evaluate(attack, `${scheme}://${address}:${daemon.port}`);
  await page.waitForTimeout(500);
  const after = takesIn(daemon);
  const status = (await api(daemon, '/status', undefined, token)).body;
  check(`${label}: a page of another origin starts no take (no-cors text/plain, CORS JSON, text/plain form)`,
        after.length === before.length && !status.recording.active, `${JSON.stringify(result)}; takes ${after.join(', ')}`);
  check(`${label}: and reads no stream frame (the WebSocket never opens)`, !result.stream.opened && result.stream.messages === 0,
        JSON.stringify(result.stream));
  check(`${label}: and reads nothing by CORS`, result.cors_read === 'blocked', String(result.cors_read));
  // A take running: the page cannot stop it.
  const started = await api(daemon, '/record/start', { take: `${label}-kept` }, token);
  check(`${label}: a script (no Origin${token ? ', bearer token' : ''}) still starts a take`, started.status === 200,
        JSON.stringify(started.body));
  await page.evaluate(attack, `${scheme}://${address}:${daemon.port}`);
  const still = (await api(daemon, '/status', undefined, token)).body;
  check(`${label}: the page cannot stop the running take`, still.recording.active === true, JSON.stringify(still.recording));
  await api(daemon, '/record/stop', {}, token);
  await page.close();
}

let browser = null;
const daemons = [];
try {
  const rebinding = `--host-resolver-rules=MAP rebind.test ${address}`;

  // ---------------------------------------------------------------- 1. loopback, no token
  if (address === '127.0.0.1' && !tls) {
    browser = await launchChromium([rebinding]);
    const open = await startDaemon('open', []);
    daemons.push(open);
    await attackAndCheck(await browser.newContext(), open, undefined, 'no token');
  }

  // ---------------------------------------------------------------- 2. token and login
  const box = await startDaemon('login', [`control.http.token_file=${join(work, 'token')}`,
                                          `control.http.viewer_token_file=${join(work, 'viewer-token')}`]);
  daemons.push(box);
  if (tls) {
    check('with TLS facecapd logs the public key pin of the certificate it made', Boolean(box.pin) &&
          box.log().includes('made now, self-signed'), box.pin);
    // Chromium trusts this key and no other: not a blanket --ignore-certificate-errors.
    browser = await launchChromium([rebinding, `--ignore-certificate-errors-spki-list=${box.pin}`]);
  } else if (!browser) {
    browser = await launchChromium([rebinding]);
  }
  const base = `${scheme}://${address}:${box.port}`;
  const context = await browser.newContext({ viewport: { width: 1400, height: 860 } });
  context.setDefaultTimeout(60000);  // a loaded 2-core machine renders the face slowly
  const page = await context.newPage();
  const pageErrors = [];
  page.on('pageerror', (e) => pageErrors.push(e.message));
  await page.goto(`${base}/`);
  await page.waitForURL(/login\.html/, { timeout: 10000 });
  check(`${address}: the dashboard sends a browser without a session to its login page`, page.url().includes('login.html?next='),
        page.url());
  await page.fill('#token', 'not-the-token');
  await page.click('#login');
  await page.waitForFunction(() => document.getElementById('login-message').classList.contains('error'), null, { timeout: 10000 });
  const refused = await page.textContent('#login-message');
  check('a wrong token is refused on the page, in words', refused.includes('the token is wrong') && refused.includes('401'), refused);
  await page.screenshot({ path: join(shots, tls ? 'login-tls.png' : 'login.png') });
  await page.fill('#token', kOperatorToken);
  await page.click('#login');
  await page.waitForURL((url) => !url.pathname.endsWith('login.html'), { timeout: 10000 });
  await page.waitForFunction(() => Number(document.body.dataset.frames ?? 0) >= 10, null, { timeout: 30000 });
  const frames = Number(await page.evaluate(() => document.body.dataset.frames));
  check(`${address}: after login the live page draws the stream`, frames >= 10, `${frames} frames`);
  const cookie = (await context.cookies()).find((c) => c.name === `facecap_session_${box.port}`);
  check(`the session cookie is HttpOnly, SameSite=Strict, expiring${tls ? ', Secure' : ''}`, cookie && cookie.httpOnly &&
        cookie.sameSite === 'Strict' && cookie.expires > Date.now() / 1000 + 3600 && cookie.secure === tls, JSON.stringify(cookie));
  await page.fill('#take', 'stage-take');
  await page.click('#record-start');
  await page.waitForFunction(() => /^recording take/.test(document.getElementById('record-message').textContent), null, { timeout: 10000 });
  await page.waitForTimeout(500);
  await page.click('#record-stop');
  await page.waitForFunction(() => /^saved /.test(document.getElementById('record-message').textContent), null,
                             { timeout: 10000 });
  check(`${address}: the logged-in page records a take`, takesIn(box).some((f) => f.includes('stage-take')), takesIn(box).join(', '));
  await page.screenshot({ path: join(shots, tls ? 'live-after-login-tls.png' : 'live-after-login.png') });

  await attackAndCheck(context, box, kOperatorToken, 'logged in');

  // DNS rebinding: a name the attacker controls, resolved to the box (chromium's resolver
  // maps rebind.test to ADDRESS), opened in the browser that holds the session.
  const rebindPage = await context.newPage();
  const rebound = (await rebindPage.goto(`${scheme}://rebind.test:${box.port}/status`)).status();
  const reboundFiles = (await rebindPage.goto(`${scheme}://rebind.test:${box.port}/`)).status();
  await rebindPage.close();
  check('DNS rebinding: Host rebind.test gets 421 for the API and the dashboard\'s files',
        rebound === 421 && reboundFiles === 421, `${rebound}, ${reboundFiles}`);

  // Logout: back to the login page; the old cookie no longer works.
  await page.click('#logout');
  await page.waitForURL(/login\.html/, { timeout: 10000 });
  const after = await send(box, '/status', { headers: { Cookie: `${cookie.name}=${cookie.value}` } });
  check('logout ends the session: its cookie gets 401', after.status === 401, `HTTP ${after.status}`);
  await page.close();  // one rendering page at a time on a small machine

  // A viewer watches but cannot record.
  const viewerContext = await browser.newContext();
  viewerContext.setDefaultTimeout(60000);
  const viewer = await viewerContext.newPage();
  viewer.on('pageerror', (e) => pageErrors.push(e.message));
  await viewer.goto(`${base}/login.html`);
  await viewer.fill('#token', kViewerToken);
  await viewer.click('#login');
  await viewer.waitForFunction(() => Number(document.body.dataset.frames ?? 0) >= 5, null, { timeout: 60000 });
  const disabled = await viewer.isDisabled('#record-start');
  const viewerPost = await viewer.evaluate(async () => (await fetch('/record/start', {
    method: 'POST', headers: { 'Content-Type': 'application/json' }, body: '{"take": "viewer-take"}' })).status);
  check('a viewer sees the stream, its Record button is disabled and POST /record/start gets 403',
        disabled && viewerPost === 403 && !takesIn(box).some((f) => f.includes('viewer-take')), `disabled ${disabled}, HTTP ${viewerPost}`);

  check('no script errors on the dashboard\'s pages', pageErrors.length === 0, pageErrors.join('; '));
} catch (e) {
  check('the test ran to its end', false, e.stack ?? String(e));
} finally {
  if (browser) await browser.close();
  attacker.close();
  for (const d of daemons) d.child.kill('SIGTERM');
  if (failed) for (const d of daemons) console.log(`facecapd's log:\n${d.log().slice(-3000)}`);
  rmSync(work, { recursive: true, force: true });
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
