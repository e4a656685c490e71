// Compiles a Flamenco job type the way Flamenco Manager does (flamenco.blender.org, Usage → Job
// Types; the Manager's job_compilers package) and prints the task graph as JSON.
// Usage: node flamenco_compile.js JOB_TYPE.js SETTINGS_JSON
// The script runs in a fresh context with the globals Flamenco gives job compiler scripts:
// `author.Task(name, type)`, `author.Command(name, parameters)`, `task.addCommand`,
// `task.addDependency`, `job.addTask`, `frameChunker(frames, chunkSize)`, `print`, `alert`.
// Everything the documented API checks is checked here too: JOB_TYPE's settings (keys, types,
// defaults, choices), required settings present, commands that Flamenco Worker implements with
// the parameter types its documentation lists, dependencies on tasks of the same job, no cycles.
"use strict";
const fs = require("fs");
const vm = require("vm");

const SETTING_TYPES = { string: "string", int32: "number", float: "number", bool: "boolean" };
// Flamenco Worker's commands (Usage → Jobs, Tasks, Commands → List of Commands) and the types of
// their parameters. `exec` takes `exe` as in that page's example and every other command (its
// table spells the parameter `exec`).
const COMMANDS = {
    "exec": { exe: "string", args: "string[]" },
    "blender-render": { exe: "string", exeArgs: "string", argsBefore: "string[]", blendfile: "string", args: "string[]" },
    "echo": { message: "string" },
    "sleep": { duration_in_seconds: "number" },
};

function fail(message) {
    process.stderr.write(`job type error: ${message}\n`);
    process.exit(1);
}

// Flamenco's frameChunker: a range like "1-10,20-25,40" (or "1..10") into chunks of at most
// chunkSize frames, each written "A-B", or "A" for one frame and "A,B" for two.
function frameChunker(frameRange, chunkSize) {
    frameRange = String(frameRange).trim();
    if (frameRange === "") throw new Error(`invalid range "${frameRange}": empty range`);
    if (!Number.isInteger(chunkSize) || chunkSize < 1) throw new Error(`invalid chunk size, must be positive number: ${chunkSize}`);
    const frames = new Set();
    for (const part of frameRange.replaceAll("..", "-").split(",")) {
        const ends = part.split("-").map((s) => s.trim());
        const parse = (s) => {
            if (!/^[+-]?\d+$/.test(s)) throw new Error(`invalid range "${frameRange}": ${part}`);
            return Number(s);
        };
        if (ends.length === 1) frames.add(parse(ends[0]));
        else if (ends.length === 2) for (let f = parse(ends[0]); f <= parse(ends[1]); f++) frames.add(f);
        else throw new Error(`invalid range "${frameRange}": ${part}`);
    }
    const sorted = [...frames].sort((a, b) => a - b);
    if (sorted.length === 0) throw new Error(`invalid range "${frameRange}": empty range`);
    const chunks = [];
    for (let i = 0; i < sorted.length; i += chunkSize) chunks.push(mergeRanges(sorted.slice(i, i + chunkSize)));
    return chunks;
}

function mergeRanges(frames) {
    const parts = [];
    let start = frames[0], prev = frames[0];
    const close = (a, b) => parts.push(a === b ? `${a}` : a + 1 === b ? `${a},${b}` : `${a}-${b}`);
    for (const f of frames.slice(1)) {
        if (f > prev + 1) { close(start, prev); start = f; }
        prev = f;
    }
    close(start, prev);
    return parts.join(",");
}

function typeOf(value) {
    if (Array.isArray(value)) return value.every((v) => typeof v === "string") ? "string[]" : "array";
    return typeof value;
}

const tasks = [];
const author = {
    Task(name, type) {
        if (typeof name !== "string" || name === "") fail(`a task needs a name, got ${JSON.stringify(name)}`);
        if (typeof type !== "string" || type === "") fail(`task ${name} needs a task type`);
        const task = { name, type, commands: [], dependencies: [] };
        task.addCommand = (command) => {
            if (!command || !COMMANDS[command.name]) fail(`task ${name}: unknown command ${JSON.stringify(command)}`);
            task.commands.push(command);
        };
        task.addDependency = (other) => {
            if (!other || typeof other.addCommand !== "function") fail(`task ${name}: a dependency must be a task`);
            task.dependencies.push(other);
        };
        return task;
    },
    Command(name, parameters) {
        const known = COMMANDS[name];
        if (!known) fail(`no Flamenco Worker command named ${JSON.stringify(name)}`);
        for (const [key, value] of Object.entries(parameters)) {
            if (!(key in known)) fail(`command ${name} has no parameter ${key}`);
            if (typeOf(value) !== known[key]) fail(`command ${name}: ${key} must be ${known[key]}, got ${JSON.stringify(value)}`);
        }
        return { name, parameters };
    },
};

function checkJobType(jobType) {
    if (!jobType || typeof jobType.label !== "string" || !Array.isArray(jobType.settings)) fail("JOB_TYPE needs a label and settings");
    const keys = new Set();
    for (const s of jobType.settings) {
        if (typeof s.key !== "string" || keys.has(s.key)) fail(`setting key ${JSON.stringify(s.key)} missing or repeated`);
        keys.add(s.key);
        if (!(s.type in SETTING_TYPES)) fail(`setting ${s.key}: unknown type ${s.type}`);
        if ("default" in s && typeof s.default !== SETTING_TYPES[s.type]) fail(`setting ${s.key}: default is not ${s.type}`);
        if (s.choices && (!Array.isArray(s.choices) || ("default" in s && !s.choices.includes(s.default)))) fail(`setting ${s.key}: bad choices`);
    }
}

function main() {
    const [scriptPath, settingsJson] = process.argv.slice(2);
    const source = fs.readFileSync(scriptPath, "utf8");
    const context = vm.createContext({ author, frameChunker, print: (...a) => process.stderr.write(a.join(" ") + "\n"), alert: () => {} });
    vm.runInContext(`${source}\n;globalThis.__jobType = JOB_TYPE; globalThis.__compile = compileJob;`, context, { filename: scriptPath });
    const jobType = context.__jobType;
    checkJobType(jobType);
    // As the Manager does on submission: defaults filled in, required settings present, choices kept.
    const settings = {};
    for (const s of jobType.settings) if ("default" in s) settings[s.key] = s.default;
    Object.assign(settings, JSON.parse(settingsJson));
    for (const s of jobType.settings) {
        if (s.required && (settings[s.key] === undefined || settings[s.key] === "")) fail(`setting ${s.key} is required`);
        if (s.key in settings && typeof settings[s.key] !== SETTING_TYPES[s.type]) fail(`setting ${s.key} must be ${s.type}`);
        if (s.choices && s.key in settings && !s.choices.includes(settings[s.key])) fail(`setting ${s.key}: ${settings[s.key]} is not a choice`);
    }
    const job = { name: "test job", settings, created: new Date(0), addTask: (t) => tasks.push(t) };
    try {
        context.__compile(job);
    } catch (e) {
        fail(`compileJob: ${e}`);
    }
    const names = new Set();
    for (const t of tasks) {
        if (names.has(t.name)) fail(`two tasks named ${t.name}`);
        names.add(t.name);
        if (t.commands.length === 0) fail(`task ${t.name} has no command`);
        for (const d of t.dependencies) if (!tasks.includes(d)) fail(`task ${t.name} depends on ${d.name}, which is not in the job`);
    }
    // No cycles: every task can be ordered after its dependencies.
    const done = new Set();
    while (done.size < tasks.length) {
        const ready = tasks.filter((t) => !done.has(t) && t.dependencies.every((d) => done.has(d)));
        if (ready.length === 0) fail("the tasks' dependencies form a cycle");
        ready.forEach((t) => done.add(t));
    }
    const graph = tasks.map((t) => ({ name: t.name, type: t.type, commands: t.commands, dependencies: t.dependencies.map((d) => d.name) }));
    process.stdout.write(JSON.stringify({ label: jobType.label, settings, tasks: graph }, null, 1) + "\n");
}

main();
