// SPDX-License-Identifier: GPL-3.0-or-later
// A Flamenco job type: bake one object of a Blender file to a PC2 point cache in frame chunks
// (one task per chunk, any worker), then one task that merges them and depends on all of them.
// Install: copy this file into the `scripts/` folder beside flamenco-manager and restart it; the
// Flamenco add-on in Blender then offers "DQ Skin Bake" as a job type.
// Each task runs the DQ Skin batch commands through the worker's `exec` command:
// `{blender} -b --command dq_skin ...` by default ({blender} is the Manager's variable for each
// worker's Blender), or `python -m dqskin.blender ...` with the bpy module. The command is split
// into words as Python's shlex.split does: at blanks, with '...', "..." and \ quoting, nothing
// expanded (`"/opt/Blender 4.5/blender" -b --command dq_skin`). The file paths are single
// arguments: spaces in them are kept.

const JOB_TYPE = {
    label: "DQ Skin Bake",
    description: "Bake DQ Skin to a PC2 point cache in frame chunks, then merge them",
    settings: [
        { key: "blendfile", type: "string", subtype: "file_path", required: true, visible: "web",
          description: "The Blender file with the object" },
        { key: "object", type: "string", required: true, eval: "C.active_object.name",
          description: "The mesh object to bake" },
        { key: "frames", type: "string", required: true,
          eval: "f'{C.scene.frame_start}-{C.scene.frame_end}'", description: "First and last frame, A-B" },
        { key: "chunk_size", type: "int32", default: 12, propargs: { min: 1 },
          description: "At most this many frames per bake task" },
        { key: "method", type: "string", default: "AUTO",
          choices: ["AUTO", "LINEAR", "DUAL_QUATERNION", "BLEND", "CENTERS_OF_ROTATION"],
          description: "AUTO keeps the object's DQ Skin method" },
        { key: "output", type: "string", subtype: "file_path", required: true,
          description: "The merged PC2 cache (chunks go to OUTPUT.chunks/)" },
        { key: "dq_skin_command", type: "string", default: "{blender} -b --command dq_skin",
          description: "The command that runs the DQ Skin batch commands, split into words as a shell does (quote a path with spaces)" },
    ],
};

function compileJob(job) {
    const settings = job.settings;
    const [first, last] = frameRange(settings.frames);
    const [exe, ...commandArgs] = splitCommand(settings.dq_skin_command);
    const chunkDir = `${settings.output}.chunks`;

    const merge = author.Task("merge", "blender");
    const chunkFiles = [];
    // frameChunker writes a chunk as "A-B", "A" or "A,B" (two frames); the bake takes A-B.
    for (const chunk of frameChunker(`${first}-${last}`, settings.chunk_size)) {
        const frames = chunk.split(/[-,]/).map(Number);
        const range = `${frames[0]}-${frames[frames.length - 1]}`;
        const out = `${chunkDir}/${range}.pc2`;
        const bake = author.Task(`bake-${range}`, "blender");
        bake.addCommand(author.Command("exec", {
            exe: exe,
            args: [...commandArgs, "bake", settings.blendfile, "--object", settings.object,
                   "--frames", range, "--method", settings.method, "--out", out],
        }));
        job.addTask(bake);
        merge.addDependency(bake);
        chunkFiles.push(out);
    }
    merge.addCommand(author.Command("exec", {
        exe: exe,
        args: [...commandArgs, "merge", settings.output, ...chunkFiles],
    }));
    job.addTask(merge);
}

// "A-B" (or Blender's "A..B") as [A, B]; the bake needs one contiguous range.
function frameRange(frames) {
    const m = /^\s*(-?\d+)\s*(?:-|\.\.)\s*(-?\d+)\s*$/.exec(frames);
    if (m === null) {
        throw `frames must look like A-B, got "${frames}"`;
    }
    const [first, last] = [Number(m[1]), Number(m[2])];
    if (last < first) {
        throw `frames ${frames}: the end is before the start`;
    }
    return [first, last];
}

// The command as words, as Python's shlex.split (a POSIX shell) splits it: at blanks, with '...',
// "..." (where \ escapes only " and \) and \ quoting; nothing is expanded.
function splitCommand(text) {
    const words = [];
    let word = "", quote = "", inWord = false;
    for (let i = 0; i < text.length; i++) {
        const c = text[i];
        if (quote === "'") {
            if (c === "'") { quote = ""; } else { word += c; }
        } else if (quote === '"') {
            if (c === '"') {
                quote = "";
            } else if (c === "\\" && (text[i + 1] === '"' || text[i + 1] === "\\")) {
                word += text[++i];
            } else {
                word += c;
            }
        } else if (/\s/.test(c)) {
            if (inWord) { words.push(word); }
            word = ""; inWord = false;
        } else {
            inWord = true;
            if (c === "'" || c === '"') {
                quote = c;
            } else if (c === "\\") {
                if (i + 1 === text.length) { throw `the DQ Skin command ends with a lone \\: ${text}`; }
                word += text[++i];
            } else {
                word += c;
            }
        }
    }
    if (quote) { throw `the DQ Skin command has no closing ${quote}: ${text}`; }
    if (inWord) { words.push(word); }
    if (words.length === 0) { throw "the DQ Skin command is empty"; }
    return words;
}
