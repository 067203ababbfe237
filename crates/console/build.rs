//! Installs the console's pinned front-end libraries (web/package-lock.json)
//! into the build directory with `npm ci`, so the binary embeds them and the
//! page works offline. Set TWINDRIVE_CONSOLE_VENDOR to a directory holding
//! `uPlot.iife.min.js` and `uPlot.min.css` to build without npm.

use std::path::{Path, PathBuf};
use std::process::Command;

const FILES: [(&str, &str); 2] = [
    (
        "uPlot.iife.min.js",
        "node_modules/uplot/dist/uPlot.iife.min.js",
    ),
    ("uPlot.min.css", "node_modules/uplot/dist/uPlot.min.css"),
];

fn main() {
    println!("cargo:rerun-if-changed=web/package.json");
    println!("cargo:rerun-if-changed=web/package-lock.json");
    println!("cargo:rerun-if-env-changed=TWINDRIVE_CONSOLE_VENDOR");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let vendor = out.join("vendor");
    std::fs::create_dir_all(&vendor).expect("creating OUT_DIR/vendor");
    if let Some(dir) = std::env::var_os("TWINDRIVE_CONSOLE_VENDOR") {
        let dir = PathBuf::from(dir);
        for (name, _) in FILES {
            copy(&dir.join(name), &vendor.join(name));
        }
        return;
    }
    let web = out.join("web");
    let installed = FILES.iter().all(|(_, path)| web.join(path).is_file());
    let lock = std::fs::read("web/package-lock.json").expect("reading web/package-lock.json");
    let same_lock = std::fs::read(web.join("package-lock.json")).is_ok_and(|l| l == lock);
    if !(installed && same_lock) {
        std::fs::create_dir_all(&web).expect("creating OUT_DIR/web");
        for name in ["package.json", "package-lock.json"] {
            copy(&Path::new("web").join(name), &web.join(name));
        }
        let npm = if cfg!(windows) { "npm.cmd" } else { "npm" };
        let status = Command::new(npm)
            .args([
                "ci",
                "--ignore-scripts",
                "--no-audit",
                "--no-fund",
                "--loglevel=error",
            ])
            .current_dir(&web)
            .status();
        match status {
            Ok(s) if s.success() => {}
            Ok(s) => panic!(
                "`npm ci` for the console's front-end libraries failed ({s}) in {}; \
                 check the network, or set TWINDRIVE_CONSOLE_VENDOR",
                web.display()
            ),
            Err(e) => panic!(
                "the console's front-end libraries are installed with npm (Node.js), \
                 which could not run: {e}; install Node.js and npm, or set TWINDRIVE_CONSOLE_VENDOR"
            ),
        }
    }
    for (name, path) in FILES {
        copy(&web.join(path), &vendor.join(name));
    }
}

fn copy(from: &Path, to: &Path) {
    std::fs::copy(from, to)
        .unwrap_or_else(|e| panic!("copying {} to {}: {e}", from.display(), to.display()));
}
