//! The HTML page of a report: a summary and sections of plots with titles
//! and captions, written atomically with its plots (nothing half-written is
//! ever left in a report directory).

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

use crate::io::atomic::write_bytes_atomic;

/// One axis in index.html: heading and its plots (file, title, caption).
pub type Section = (String, Vec<(String, String, String)>);

/// One report file: its name in the report directory and its content.
pub struct Page {
    pub name: String,
    pub content: String,
}

/// Create `dir` if needed and write `pages` atomically; on error remove what
/// this call created (files that did not exist before, and `dir` if it was
/// created here and is empty again).
pub fn write_pages(dir: &Path, pages: &[Page]) -> Result<Vec<PathBuf>> {
    let dir_existed = dir.is_dir();
    if !dir_existed {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create the report directory", dir.display()))?;
    }
    let mut written: Vec<PathBuf> = Vec::new();
    let mut created: Vec<PathBuf> = Vec::new();
    for p in pages {
        let path = dir.join(&p.name);
        let existed = path.exists();
        if let Err(e) = write_bytes_atomic(&path, p.content.as_bytes()) {
            for c in &created {
                let _ = std::fs::remove_file(c);
            }
            if !dir_existed {
                let _ = std::fs::remove_dir(dir);
            }
            return Err(e);
        }
        if !existed {
            created.push(path.clone());
        }
        written.push(path);
    }
    Ok(written)
}

pub fn html_escape(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// The report page: `title`, `summary` as preformatted text, then each
/// section's plots with their titles and captions.
pub fn index_html(title: &str, summary: &str, sections: &[Section]) -> String {
    let mut h = String::new();
    h.push_str(
        &"<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{title}</title>\n\
         <style>\n\
         body { font-family: sans-serif; margin: 2em auto; max-width: 1150px; padding: 0 1em; color: #222; }\n\
         pre { background: #f4f4f4; border: 1px solid #ddd; padding: 1em; white-space: pre-wrap; overflow-wrap: anywhere; }\n\
         img { width: 100%; max-width: 1100px; border: 1px solid #ddd; }\n\
         nav a { margin-right: 1em; }\n\
         p.caption { color: #444; }\n\
         </style>\n</head>\n<body>\n<h1>{title}</h1>\n"
            .replace("{title}", &html_escape(title)),
    );
    if !sections.is_empty() {
        h.push_str("<nav>");
        for (sec_title, entries) in sections {
            if let Some((file, _, _)) = entries.first() {
                let anchor = file.split('_').next().unwrap_or("");
                h.push_str(&format!("<a href=\"#axis-{}\">{}</a>", html_escape(anchor), html_escape(sec_title)));
            }
        }
        h.push_str("</nav>\n");
    }
    h.push_str("<h2>Summary</h2>\n<pre>");
    h.push_str(&html_escape(summary));
    h.push_str("</pre>\n");
    for (title, entries) in sections {
        let anchor = entries.first().map(|e| e.0.split('_').next().unwrap_or("")).unwrap_or("");
        h.push_str(&format!("<h2 id=\"axis-{}\">{}</h2>\n", html_escape(anchor), html_escape(title)));
        for (file, plot_title, caption) in entries {
            h.push_str(&format!(
                "<h3>{}</h3>\n<p class=\"caption\">{}</p>\n<p><a href=\"{f}\"><img src=\"{f}\" alt=\"{}\"></a></p>\n",
                html_escape(plot_title),
                html_escape(caption),
                html_escape(plot_title),
                f = html_escape(file),
            ));
        }
    }
    h.push_str("</body>\n</html>\n");
    h
}
