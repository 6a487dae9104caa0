//! The mapper's OpenAPI document as the tests hold the server to it: each JSON answer
//! validates against the schema documented for its route, and every documented route is
//! served.

use serde_json::{Value, json};

/// The document, fetched from a running mapper.
pub struct OpenApiDoc {
    doc: Value,
}

impl OpenApiDoc {
    pub fn fetch(http: &str) -> OpenApiDoc {
        Self::fetch_with(http, None)
    }

    /// The document from a mapper that wants a bearer token to read.
    pub fn fetch_with(http: &str, token: Option<&str>) -> OpenApiDoc {
        let doc = super::get_json_with(http, "/api/v1/openapi.json", token)
            .expect("the OpenAPI document");
        assert!(
            doc["openapi"].as_str().is_some_and(|v| v.starts_with("3.")),
            "{doc}"
        );
        OpenApiDoc { doc }
    }

    /// Every documented (path template, method, response content types of 200).
    pub fn operations(&self) -> Vec<(String, String, Vec<String>)> {
        let mut out = Vec::new();
        for (path, item) in self.doc["paths"].as_object().expect("paths") {
            for (method, op) in item.as_object().expect("operations") {
                let types = op["responses"]["200"]["content"]
                    .as_object()
                    .map(|c| c.keys().cloned().collect())
                    .unwrap_or_default();
                out.push((path.clone(), method.clone(), types));
            }
        }
        out
    }

    /// The documented path template that `path` (query ignored) is an instance of.
    pub fn template_of(&self, path: &str) -> Option<String> {
        let path = path.split('?').next().unwrap_or(path);
        let parts: Vec<&str> = path.split('/').collect();
        self.doc["paths"]
            .as_object()?
            .keys()
            .find(|template| {
                let t: Vec<&str> = template.split('/').collect();
                t.len() == parts.len()
                    && t.iter().zip(&parts).all(|(t, p)| {
                        if t.starts_with('{') && t.ends_with('}') {
                            !p.is_empty()
                        } else {
                            t == p
                        }
                    })
            })
            .cloned()
    }

    /// Checks a 200 JSON answer of `GET path` against its documented schema; panics naming
    /// every violation.
    pub fn check_json(&self, path: &str, body: &Value) {
        let errors = self.violations(path, body);
        assert!(
            errors.is_empty(),
            "GET {path} does not match its schema:\n{}",
            errors.join("\n")
        );
    }

    /// How a JSON answer of `GET path` departs from its documented schema (none: it fits).
    pub fn violations(&self, path: &str, body: &Value) -> Vec<String> {
        let template = self
            .template_of(path)
            .unwrap_or_else(|| panic!("GET {path}: no such route in the document"));
        let content = &self.doc["paths"][&template]["get"]["responses"]["200"]["content"];
        // application/json, or a JSON type of its own (application/geo+json).
        let schema = content
            .as_object()
            .and_then(|c| {
                c.iter()
                    .find(|(t, _)| *t == "application/json" || t.ends_with("+json"))
            })
            .map_or(&Value::Null, |(_, media)| &media["schema"]);
        assert!(
            schema.is_object(),
            "GET {template}: no JSON schema documented ({content})"
        );
        // The schema with the document's components beside it, so its $refs resolve.
        let mut root = schema.clone();
        root["components"] = self.doc["components"].clone();
        root["$schema"] = json!("https://json-schema.org/draft/2020-12/schema");
        let validator = jsonschema::validator_for(&root)
            .unwrap_or_else(|e| panic!("GET {template}: the schema does not compile: {e}"));
        validator
            .iter_errors(body)
            .map(|e| format!("{template}: {} at {}", e, e.instance_path()))
            .collect()
    }
}
