// Drives the coordinator's live page in a real browser (page-test.sh starts the farm):
// node page_test.mjs CHROMIUM URL JOB ALICE_TOKEN VIEWER_TOKEN ADMIN_TOKEN
import puppeteer from 'puppeteer-core';

const [chromium, url, job, alice, viewer, admin] = process.argv.slice(2);
const failures = [];
const check = (ok, what) => { console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`); if (!ok) failures.push(what); };

const browser = await puppeteer.launch({executablePath: chromium, headless: true,
                                        args: ['--no-sandbox', '--disable-gpu', '--no-first-run']});
try {
  const page = await browser.newPage();
  const dialogs = [];
  page.on('dialog', async d => {
    dialogs.push(d.type());
    if (d.type() === 'prompt') await d.accept('7');
    else if (d.type() === 'confirm') await d.accept();
    else await d.dismiss();  // an alert: only injected script would raise one
  });
  const pageErrors = [];
  page.on('pageerror', e => pageErrors.push(e.message));
  // The page itself needs a reader's token: the browser's Basic prompt, answered here.
  await page.authenticate({username: '', password: viewer});
  const res = await page.goto(url, {waitUntil: 'load'});
  check(res.status() === 200, 'the page loads with a viewer token');
  const text = id => page.$eval(id, e => e.textContent);
  const until = (fn, ...args) => page.waitForFunction(fn, {timeout: 45000}, ...args);
  await until(j => document.getElementById('jobs').textContent.includes(j), job);
  check(true, 'the jobs table lists the job');
  await until(() => document.getElementById('workers').rows.length > 1);

  // Hostile names are shown as text, never run or parsed as markup.
  check(await page.evaluate(() => document.getElementById('pwned') === null && window.pwned === undefined),
        'no element or script from a hostile name');
  check((await text('#jobs')).includes('job<img src=x id=pwned onerror=alert(1)><script>'), 'the job name shown as text');
  check((await text('#workers')).includes('w<img src=x id=pwned'), 'the worker name shown as text');
  await until(() => document.getElementById('events').textContent.includes('worker.registered'));
  check((await text('#events')).includes('w<img src=x id=pwned'), 'events show the worker name as text');

  const setToken = t => page.$eval('#token', (e, v) => { e.value = v; e.dispatchEvent(new Event('change')); }, t);
  // Clicks the button `act` of the job with id `id` (or of the worker named `id`) as soon
  // as the page shows it. Found and clicked in one synchronous step: the page redraws its
  // tables every second, and a button a redraw replaced no longer reaches the page's
  // handler. A worker is found by its name: its id would change if it registered again.
  const click = (kind, id, act) => until((k, i, a) => {
    const b = [...document.querySelectorAll(`button[data-kind="${k}"][data-act="${a}"]`)].find(b =>
      k === 'workers' ? b.closest('tr').cells[1].textContent === i : b.dataset.id === i);
    if (!b) return false;
    b.click();
    return true;
  }, kind, id, act);
  const state = () => page.evaluate(j => {
    const row = [...document.querySelectorAll('#jobs tr.job')].find(r => r.dataset.id === j);
    return row ? row.cells[4].textContent : null;
  }, job);

  // Without a token of its own the page may read, not act: HTTP Basic is refused for actions.
  await click('jobs', job, 'cancel');
  await until(() => document.getElementById('error').textContent.length > 0);
  check((await text('#error')).includes('Bearer'), 'an action with the browser\'s Basic credentials is refused');
  // A viewer's token: refused, saying so; the job goes on.
  await setToken(viewer);
  await page.evaluate(() => { document.getElementById('error').textContent = ''; });
  await click('jobs', job, 'cancel');
  await until(() => document.getElementById('error').textContent.length > 0);
  check(['QUEUED', 'RUNNING'].includes(await state()), `a viewer cannot cancel (${await text('#error')})`);

  // The owner: a priority (the prompt answered 7), then cancel.
  await setToken(alice);
  await click('jobs', job, 'priority');
  await until(j => [...document.querySelectorAll('#jobs tr.job')].some(r => r.dataset.id === j && r.cells[3].textContent === '7'), job);
  check(dialogs.includes('prompt'), 'priority asks for the new value and sets it');
  await click('jobs', job, 'cancel');
  await until(j => [...document.querySelectorAll('#jobs tr.job')].some(r => r.dataset.id === j && r.cells[4].textContent === 'CANCELLED'), job);
  check(true, 'the owner cancels the job');

  // A worker: drain and resume, as an admin.
  const worker = await (await until(() => document.querySelector('#workers button[data-act]')?.closest('tr').cells[1].textContent)).jsonValue();
  await click('workers', worker, 'drain');
  await until(() => document.getElementById('error').textContent.includes('only an admin'));
  check(true, 'a client may not drain a worker');
  await setToken(admin);
  await click('workers', worker, 'drain');
  await until(() => document.getElementById('workers').textContent.includes('draining'));
  await click('workers', worker, 'resume');
  await until(() => !document.getElementById('workers').textContent.includes('draining'));
  check(true, 'an admin drains and resumes the worker');

  // A job's detail: click its row; its settings and its own events.
  await page.evaluate(j => [...document.querySelectorAll('#jobs tr.job')].find(r => r.dataset.id === j).click(), job);
  await until(() => document.getElementById('settings').textContent.includes('"width"'));
  await until(() => document.getElementById('job-events').textContent.includes('job.cancelled'));
  const events = await text('#job-events');
  check(events.includes('job.priority') && events.includes('alice'), 'the job\'s events say who changed it');
  check((await text('#shown')).includes(job), 'the clicked job is shown');
  check(!dialogs.includes('alert'), 'no alert was ever raised');
  check(pageErrors.length === 0, `no script error (${pageErrors.join('; ')})`);
} finally {
  await browser.close();
}
if (failures.length) { console.log(`${failures.length} failed`); process.exit(1); }
console.log('PASS: the live page in chromium');
