import { spawn } from 'node:child_process';
import readline from 'node:readline';
const p = spawn('node', ['src/main.js', '--elf', process.argv[2]], { stdio: ['pipe', 'pipe', 'inherit'] });
const rl = readline.createInterface({ input: p.stdout });
const it = rl[Symbol.asyncIterator]();
await it.next();
let t = 0;
async function req(o) { p.stdin.write(JSON.stringify(o) + '\n'); return JSON.parse((await it.next()).value); }
for (let i = 0; i < 1000; i++) {
  t += 500000;
  if (i === 400) console.log(await req({op:'hang'}));
  const r = await req({op:'run', until_ns:t, proximity_v:1.2, manometer_v:0.33, load_counts:1000, adc_noise_lsb:1.5, hx711_period_ns:12.5e6});
  if (r.error) { console.log(r); break; }
  if (r.resets.length) console.log(i, 'reset', r.resets);
}
const r = await req({op:'report'}); console.log(JSON.stringify(r.resets), r.usb.vid, r.usb.pid, r.ticks);
p.stdin.end();
