//! report.html, as a colleague handed it opens it: the demo's study is run (`twinbench
//! demo` on the bundled Spielberg lap, with 4 generations a step: ~10 s), then its page is
//! 1. read: self-contained (no address of the network in a `src`, `href`, `url(` or
//!    `@import`; no script, no linked file), one inline picture per plot, the four wheel
//!    loads among them, the inputs' SHA-256 and the lap's truth in it;
//! 2. opened in headless Chromium with the network off (`unshare -n` where it works, and
//!    every host name resolving nowhere): a screenshot that is not blank, and a copy of the
//!    page with a script appended that counts the pictures the browser laid out with a
//!    size and something drawn in them, read back from the DOM.
//!
//! Chromium is Debian's package (`apt-get install chromium`; tools/chromium.sh installs it
//! for tools/test.sh and CI): without it this test fails, saying so.

use sha2::Digest;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const CHROMIUM: &str = "/usr/bin/chromium";
const WINDOW: (u32, u32) = (1400, 4000);

#[test]
fn the_demos_report_html_is_self_contained_and_renders_every_picture_offline() {
    assert!(
        Path::new(CHROMIUM).is_file(),
        "{CHROMIUM} is missing: this test opens report.html in headless Chromium; install it \
         with `apt-get install chromium` (tools/chromium.sh does, as tools/test.sh runs it)"
    );
    let dir = tb_testkit::scratch("report-html");
    let d = dir.path();
    // The bundled study with 4 generations a step instead of 22: the page is the same
    // page, in a third of the time.
    let study = include_str!("../studies/spielberg.toml")
        .replace("\ngenerations = 22\n", "\ngenerations = 4\n");
    assert!(study.contains("generations = 4"));
    let quick = d.join("demo/bundle/studies/quick.toml");
    std::fs::create_dir_all(quick.parent().unwrap()).unwrap();
    std::fs::write(&quick, study).unwrap();
    let started = Instant::now();
    let o = Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .args(["demo", "--out", "demo", "--study"])
        .arg(&quick)
        .current_dir(d)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("demo/report.html"), "listed: {stdout}");
    eprintln!("demo: {:.1} s", started.elapsed().as_secs_f64());

    let page = d.join("demo/report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    let expected = expected_pictures(&d.join("demo"), &html);
    check_text(&html, &quick);

    let started = Instant::now();
    let profile = d.join("chromium");
    let screenshot = d.join("report.png");
    let shot = chromium(
        &profile,
        &[
            format!("--screenshot={}", screenshot.display()),
            format!("--window-size={},{}", WINDOW.0, WINDOW.1),
        ],
        &page,
    );
    assert!(
        screenshot.is_file(),
        "no screenshot: {}",
        String::from_utf8_lossy(&shot.stderr)
    );
    check_screenshot(&screenshot);
    let rendered = rendered_pictures(&profile, &html, d);
    assert_eq!(
        rendered,
        format!("rendered {expected} of {expected}"),
        "every picture drawn with a size"
    );
    eprintln!("Chromium: {:.1} s", started.elapsed().as_secs_f64());
}

/// The pictures the page must have: the parameters' one, one per signal of the study and
/// wheel load, and the study's plots (Fz_sum filtered is among the signals).
fn expected_pictures(folder: &Path, html: &str) -> usize {
    let svg_files = std::fs::read_dir(folder)
        .unwrap()
        .filter(|e| {
            let name = e.as_ref().unwrap().file_name();
            let name = name.to_string_lossy();
            name.ends_with(".svg") && name != "fz_sum_filtered.svg"
        })
        .count();
    // The bundled study fits Fz_front, Fz_rear, Fz_sum and the four wheel loads.
    let signals = [
        "Fz_front", "Fz_rear", "Fz_sum", "Fz_rl", "Fz_rr", "Fz_fl", "Fz_fr",
    ];
    for s in signals {
        assert!(
            html.contains(&format!("<figcaption>{s}</figcaption>")),
            "no figure of {s}"
        );
    }
    let expected = 1 + signals.len() + svg_files;
    let figures = html.matches("<figure class=\"plot\"><svg").count();
    assert_eq!(figures, expected, "one inline SVG per picture");
    assert_eq!(html.matches("<figure").count(), expected);
    expected
}

/// Self-contained, and the contents the issue asks for.
fn check_text(html: &str, study: &Path) {
    let lower = html.to_lowercase();
    for attribute in ["src=", "href=", "url(", "@import"] {
        for (at, _) in lower.match_indices(attribute) {
            let value = lower[at + attribute.len()..].trim_start_matches(['"', '\'', ' ']);
            assert!(
                !(value.starts_with("http:")
                    || value.starts_with("https:")
                    || value.starts_with("//")),
                "a network reference: {}",
                &html[at..(at + 80).min(html.len())]
            );
        }
    }
    for tag in ["<script", "<link", "<img", "<iframe", "<object", "<embed"] {
        assert!(!lower.contains(tag), "{tag} in the page");
    }
    for text in [
        "<title>twinbench report: study spielberg</title>",
        "Tab. 1",
        "The values to load into the bench",
        "Model check:",
        "truth of the lap",
        "Provenance",
        env!("CARGO_PKG_VERSION"),
    ] {
        assert!(html.contains(text), "no {text:?} in the page");
    }
    // The digests are the files'.
    let digest = format!("{:x}", sha2::Sha256::digest(std::fs::read(study).unwrap()));
    assert!(html.contains(&digest), "no SHA-256 of the study file");
    assert!(
        html.matches("<td class=\"hash\">").count() >= 7,
        "study, system, 4 FMUs, measurement, truth"
    );
}

/// Headless Chromium on `page` with the network off; its output (fails after 90 s).
fn chromium(profile: &Path, extra: &[String], page: &Path) -> Output {
    // Chromium writes into the temporary folder and the home folder: both in the
    // scratch folder, so that nothing stays behind.
    let home = profile.join("home");
    std::fs::create_dir_all(&home).unwrap();
    // Its singleton socket goes into its temporary folder, and a socket's path has at most
    // 107 bytes: a clone's deep scratch folder is too long ("Socket path too long"), so a
    // short folder under /tmp, removed when Chromium is done.
    let sockets = tempfile::Builder::new()
        .prefix("tb-chromium-")
        .tempdir_in("/tmp")
        .unwrap();
    let offline = Command::new("unshare")
        .args(["-n", "true"])
        .status()
        .is_ok_and(|s| s.success());
    let mut c = match offline {
        true => {
            let mut c = Command::new("unshare");
            c.args(["-n", CHROMIUM]);
            c
        }
        false => Command::new(CHROMIUM),
    };
    c.args([
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--hide-scrollbars",
        "--host-resolver-rules=MAP * ~NOTFOUND",
    ])
    .arg(format!(
        "--user-data-dir={}",
        profile.join("data").display()
    ))
    .args(extra)
    .arg(format!("file://{}", page.display()))
    .env("HOME", &home)
    .env("TMPDIR", sockets.path())
    .env("XDG_CONFIG_HOME", &home)
    .env("XDG_CACHE_HOME", &home);
    // Into files, not pipes: a DOM of a megabyte would fill a pipe read only at the end.
    let (out, err) = (profile.join("stdout"), profile.join("stderr"));
    c.stdin(Stdio::null())
        .stdout(std::fs::File::create(&out).unwrap())
        .stderr(std::fs::File::create(&err).unwrap());
    let mut child = c.spawn().expect("Chromium starts");
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > Duration::from_secs(90) {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "Chromium did not finish in 90 s: {}",
                std::fs::read_to_string(&err).unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    Output {
        status,
        stdout: std::fs::read(&out).unwrap(),
        stderr: std::fs::read(&err).unwrap(),
    }
}

/// The screenshot has the window's size and is not blank: a good share of it is ink, in
/// many colours (text, lines of several series, the header).
fn check_screenshot(path: &Path) {
    let mut decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), WINDOW, "the screenshot's size");
    let channels = info.color_type.samples();
    assert!(channels >= 3, "{:?}", info.color_type);
    let pixels = buf[..info.buffer_size()].chunks(channels);
    let (mut ink, mut total) = (0usize, 0usize);
    let mut colours = std::collections::HashSet::new();
    for p in pixels {
        total += 1;
        if p[..3].iter().any(|&c| c < 235) {
            ink += 1;
        }
        colours.insert((p[0] >> 3, p[1] >> 3, p[2] >> 3));
    }
    let share = ink as f64 / total as f64;
    eprintln!(
        "screenshot: {:.1} % ink, {} colours",
        100.0 * share,
        colours.len()
    );
    assert!(share > 0.03, "the screenshot is nearly blank ({share:.4})");
    assert!(colours.len() > 50, "{} colours only", colours.len());
}

/// A copy of the page with a script that counts, once laid out, the pictures with a size
/// and drawn content, into the title; Chromium's DOM read back. The page itself stays
/// script-free.
fn rendered_pictures(profile: &Path, html: &str, d: &Path) -> String {
    const COUNT: &str = r#"<script>
addEventListener("load", () => {
  const pictures = [...document.querySelectorAll("figure.plot > svg")];
  const drawn = pictures.filter(p => {
    const r = p.getBoundingClientRect();
    return r.width > 100 && r.height > 50
      && p.querySelectorAll("path, polyline, line, rect, circle, polygon, text").length > 0;
  });
  document.title = `rendered ${drawn.length} of ${pictures.length}`;
});
</script></body>"#;
    assert_eq!(html.matches("</body>").count(), 1);
    let copy: PathBuf = d.join("report_counted.html");
    std::fs::write(&copy, html.replace("</body>", COUNT)).unwrap();
    let o = chromium(profile, &["--dump-dom".to_string()], &copy);
    let dom = String::from_utf8_lossy(&o.stdout);
    let title = dom
        .split_once("<title>")
        .and_then(|(_, rest)| rest.split_once("</title>"))
        .map(|(t, _)| t.to_string());
    title.unwrap_or_else(|| {
        panic!(
            "no title in Chromium's DOM: {}",
            String::from_utf8_lossy(&o.stderr)
        )
    })
}
