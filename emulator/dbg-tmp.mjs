import fs from 'node:fs';
import { createChip } from './src/chip.js';
import { loadElfIntoFlash } from './src/elf.js';
const rom = fs.readFileSync('rom/bootrom-b1.bin');
const bootrom = new Uint32Array(rom.buffer, rom.byteOffset, 4096).slice();
const image = new Uint8Array(16*1024*1024).fill(0xff);
loadElfIntoFlash(fs.readFileSync(process.argv[2]), image);
const { rp, watchdog } = createChip({ bootrom, image, uniqueId:[1,2,3,4,5,6,7,8], resetReason: Number(process.argv[3]), scratch: null, runBootrom: false, verbose: true });
let trig = 0; watchdog.onWatchdogTrigger = () => { trig++; };
const core = rp.core, clock = rp.clock;
let n = 0; const start = Date.now();
while (clock.nanos < 300e6 && Date.now() - start < 5000) {
  if (core.waiting) { const next = clock.nextAlarm ? clock.nextAlarm.nanos : 300e6; clock.tick(Math.max(0, Math.min(next, 300e6) - clock.nanos)); }
  else clock.tick(core.executeInstruction() * 8);
  n++;
}
console.log('nanos', clock.nanos, 'instr', n, 'PC', core.PC.toString(16), 'waiting', core.waiting, 'trig', trig);
