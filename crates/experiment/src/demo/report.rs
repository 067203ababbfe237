//! A small document model for the demo's report, rendered twice: Markdown
//! (figures linked, the PNG where there is one) and one self-contained HTML
//! page (SVG figures inlined).

use std::path::{Path, PathBuf};

use anyhow::Context;

/// One block of the report.
pub enum Block {
    Heading(u8, String),
    Paragraph(String),
    /// Header cells, then rows.
    Table(Vec<String>, Vec<Vec<String>>),
    /// A figure's path relative to the report's directory without its
    /// extension (`<base>.png` and `<base>.svg`, as twindrive-plot writes
    /// them), and its caption.
    Figure(PathBuf, String),
}

/// The report: blocks in order.
#[derive(Default)]
pub struct Report {
    pub blocks: Vec<Block>,
}

impl Report {
    pub fn heading(&mut self, level: u8, text: impl Into<String>) {
        self.blocks.push(Block::Heading(level, text.into()));
    }

    /// A paragraph; runs of whitespace (source line breaks) become one space.
    pub fn paragraph(&mut self, text: impl Into<String>) {
        let text: String = text.into();
        let words: Vec<&str> = text.split_whitespace().collect();
        self.blocks.push(Block::Paragraph(words.join(" ")));
    }

    pub fn table(&mut self, header: &[&str], rows: Vec<Vec<String>>) {
        self.blocks.push(Block::Table(
            header.iter().map(|h| (*h).to_string()).collect(),
            rows,
        ));
    }

    /// A figure: `base` without extension, relative to the report.
    pub fn figure(&mut self, base: impl Into<PathBuf>, caption: impl Into<String>) {
        self.blocks.push(Block::Figure(base.into(), caption.into()));
    }

    /// The Markdown of the report written into `dir`: each figure links its
    /// PNG, or its SVG where there is no PNG; a figure with neither is an
    /// error.
    pub fn markdown(&self, dir: &Path) -> anyhow::Result<String> {
        let mut md = String::new();
        for b in &self.blocks {
            match b {
                Block::Heading(level, text) => {
                    md.push_str(&format!("{} {text}\n\n", "#".repeat(*level as usize)));
                }
                Block::Paragraph(text) => md.push_str(&format!("{text}\n\n")),
                Block::Table(header, rows) => {
                    md.push_str(&format!("| {} |\n", header.join(" | ")));
                    md.push_str(&format!("|{}\n", "---|".repeat(header.len())));
                    for r in rows {
                        md.push_str(&format!("| {} |\n", r.join(" | ")));
                    }
                    md.push('\n');
                }
                Block::Figure(base, caption) => {
                    let link = ["png", "svg"]
                        .iter()
                        .map(|ext| base.with_extension(ext))
                        .find(|f| dir.join(f).is_file())
                        .with_context(|| {
                            format!(
                                "the report's figure {}: neither .png nor .svg in {}",
                                base.display(),
                                dir.display()
                            )
                        })?;
                    md.push_str(&format!(
                        "![{caption}]({})\n\n*{caption}*\n\n",
                        link.display()
                    ));
                }
            }
        }
        Ok(md)
    }

    /// One HTML page; figures are read from `dir` and inlined.
    pub fn html(&self, title: &str, dir: &Path) -> anyhow::Result<String> {
        let mut h = String::new();
        h.push_str(&format!(
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>\n{STYLE}</style>\n</head>\n<body>\n",
            escape(title)
        ));
        for b in &self.blocks {
            match b {
                Block::Heading(level, text) => {
                    h.push_str(&format!("<h{level}>{}</h{level}>\n", inline(text)));
                }
                Block::Paragraph(text) => h.push_str(&format!("<p>{}</p>\n", inline(text))),
                Block::Table(header, rows) => {
                    h.push_str("<table>\n<tr>");
                    for c in header {
                        h.push_str(&format!("<th>{}</th>", inline(c)));
                    }
                    h.push_str("</tr>\n");
                    for r in rows {
                        h.push_str("<tr>");
                        for c in r {
                            h.push_str(&format!("<td>{}</td>", inline(c)));
                        }
                        h.push_str("</tr>\n");
                    }
                    h.push_str("</table>\n");
                }
                Block::Figure(base, caption) => {
                    let file = dir.join(base.with_extension("svg"));
                    let svg = std::fs::read_to_string(&file)
                        .with_context(|| format!("reading figure {}", file.display()))?;
                    // Drop an XML declaration; the SVG element itself is valid HTML.
                    let svg = svg.find("<svg").map_or(svg.as_str(), |start| &svg[start..]);
                    h.push_str(&format!(
                        "<figure>\n{svg}\n<figcaption>{}</figcaption>\n</figure>\n",
                        inline(caption)
                    ));
                }
            }
        }
        h.push_str("</body>\n</html>\n");
        Ok(h)
    }
}

const STYLE: &str = "body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; line-height: 1.5; color: #222; }
table { border-collapse: collapse; margin: 1em 0; }
th, td { border: 1px solid #bbb; padding: 0.3em 0.6em; text-align: right; }
th { background: #f0f0f0; }
td:first-child, th:first-child { text-align: left; }
figure { margin: 1.5em 0; }
figure svg { max-width: 100%; height: auto; }
figcaption { font-style: italic; color: #555; }
code { background: #f4f4f4; padding: 0 0.2em; }
";

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Escapes text and turns `code` spans into <code>.
fn inline(text: &str) -> String {
    let escaped = escape(text);
    let mut out = String::new();
    for (k, part) in escaped.split('`').enumerate() {
        if k % 2 == 1 {
            out.push_str(&format!("<code>{part}</code>"));
        } else {
            out.push_str(part);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markdown_and_html_carry_the_same_content() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("f.svg"),
            "<?xml version=\"1.0\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\"><rect/></svg>",
        )
        .unwrap();
        let mut r = Report::default();
        r.heading(1, "Case <study>");
        r.paragraph("Run   `twindrive demo`.\n   Then read.");
        r.table(&["a", "b"], vec![vec!["1".into(), "2 & 3".into()]]);
        r.figure("f", "A figure");
        let md = r.markdown(dir.path()).unwrap();
        assert!(md.contains("# Case <study>"));
        assert!(md.contains("| a | b |\n|---|---|\n| 1 | 2 & 3 |"));
        // No PNG beside it: the SVG.
        assert!(md.contains("![A figure](f.svg)"), "{md}");
        let html = r.html("t", dir.path()).unwrap();
        assert!(html.contains("<h1>Case &lt;study&gt;</h1>"));
        assert!(html.contains("Run <code>twindrive demo</code>. Then read."));
        assert!(html.contains("<td>2 &amp; 3</td>"));
        assert!(html.contains("<svg xmlns") && !html.contains("<?xml"));
        assert!(r.html("t", Path::new("/nonexistent")).is_err());
    }

    #[test]
    fn markdown_links_the_png_where_there_is_one_and_fails_without_either() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        for f in ["sub/a.svg", "sub/a.png", "b.svg"] {
            std::fs::write(dir.path().join(f), "x").unwrap();
        }
        let mut r = Report::default();
        r.figure("sub/a", "A");
        r.figure("b", "B");
        let md = r.markdown(dir.path()).unwrap();
        assert!(
            md.contains("![A](sub/a.png)") && !md.contains("a.svg"),
            "{md}"
        );
        assert!(md.contains("![B](b.svg)"), "{md}");
        r.figure("missing/c", "C");
        let err = format!("{:#}", r.markdown(dir.path()).unwrap_err());
        assert!(
            err.contains("missing/c") && err.contains("neither .png nor .svg"),
            "{err}"
        );
    }
}
