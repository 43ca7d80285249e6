//! The config describing itself, generated from its types so that it cannot drift: the JSON
//! Schema of the TOML config (`stagerl config --format json-schema`, for editors) and the
//! annotated listing `stagerl config` prints: every section and field with its default and one
//! line of help (the first sentence of the field's documentation, which names its unit), the
//! allowed values of a choice, and the optional sections as commented examples
//! (`# [task.random_obstacles]`) with their own defaults.
//!
//! A default is the schema's (serde's field defaults) or, for a field a run's `config.toml`
//! leaves out while it has its default value (`observe_obstacles`, `task.sim`, ...), found by
//! reading each candidate value (a choice's values, `false`, `0`, `1`, `2`, `[]`) into a config and keeping
//! the one that gives the default config.

use serde_json::Value;

use super::Config;

/// The JSON Schema (draft 2020-12) of the config file.
pub fn json_schema() -> Value {
    serde_json::to_value(schemars::schema_for!(Config)).expect("a schema is JSON")
}

/// The annotated listing of every section and field (valid TOML: the optional parts are
/// comments, the rest is the default config).
pub fn annotated_toml() -> String {
    let schema = json_schema();
    let mut out = String::from(
        "# stagerl's config: every section and field with its default and one line of help.\n\
         # Lines starting with `# ` and holding `name = value` are optional settings, unset by\n\
         # default; uncomment to set them. Units are in the names (_m metres, _rad radians,\n\
         # _s seconds) or in the help. `stagerl config --format json-schema` writes the schema.\n",
    );
    let order = written_order();
    let root = schema["properties"].as_object().expect("the config is an object");
    let mut listing = Listing { schema: &schema, out: &mut out, order: &order };
    for (section, prop) in listing.sorted("", root) {
        let Some(def) = resolve(&schema, prop) else { continue };
        listing.section(section, def, false, false);
    }
    out
}

/// The sections and fields in the order a written config has them (the types' order), as
/// `section.field` paths.
fn written_order() -> Vec<String> {
    let mut order = Vec::new();
    let mut section = String::new();
    for line in Config::default().to_toml_string().lines() {
        if let Some(s) = line.strip_prefix('[').and_then(|s| s.strip_suffix(']')) {
            section = s.to_string();
            order.push(section.clone());
        } else if let Some((name, _)) = line.split_once(" = ") {
            order.push(format!("{section}.{name}"));
        }
    }
    order
}

/// Every required setting `table` (a config file's TOML) lacks, as `section.field` paths
/// (`task.obstacles[1].position_m`): serde names the first missing field only, a user wants
/// them all at once.
pub fn missing_required(table: &toml::Table) -> Vec<String> {
    let schema = json_schema();
    let mut out = Vec::new();
    missing_in(&schema, &schema, table, "", &mut out);
    out
}

fn missing_in(schema: &Value, node: &Value, table: &toml::Table, path: &str, out: &mut Vec<String>) {
    let at = |name: &str| if path.is_empty() { name.to_string() } else { format!("{path}.{name}") };
    for name in node.get("required").and_then(Value::as_array).into_iter().flatten().filter_map(Value::as_str)
    {
        if !table.contains_key(name) {
            out.push(at(name));
        }
    }
    let Some(props) = node.get("properties").and_then(Value::as_object) else { return };
    for (name, value) in table {
        let Some(def) = props.get(name).and_then(|p| resolve(schema, p)) else { continue };
        match value {
            toml::Value::Table(t) => missing_in(schema, def, t, &at(name), out),
            toml::Value::Array(items) => {
                for (i, item) in items.iter().enumerate() {
                    if let toml::Value::Table(t) = item {
                        missing_in(schema, def, t, &format!("{}[{i}]", at(name)), out);
                    }
                }
            }
            _ => {}
        }
    }
}

/// A `$ref` (or a nullable `anyOf` of one) resolved to its definition.
fn resolve<'a>(schema: &'a Value, prop: &'a Value) -> Option<&'a Value> {
    let target = prop
        .get("$ref")
        .or_else(|| prop.get("anyOf")?.as_array()?.iter().find_map(|v| v.get("$ref")))
        .or_else(|| prop.get("items")?.get("$ref"))?;
    let name = target.as_str()?.strip_prefix("#/$defs/")?;
    schema["$defs"].get(name)
}

/// The printed listing under way.
struct Listing<'a> {
    schema: &'a Value,
    out: &'a mut String,
    /// [`written_order`].
    order: &'a [String],
}

impl<'a> Listing<'a> {
    /// A section (`[path]`, `[[path]]` when `array`), commented out when `optional`, then its
    /// sub-sections.
    fn section(&mut self, path: &str, def: &'a Value, optional: bool, array: bool) {
        let c = if optional { "# " } else { "" };
        self.out.push('\n');
        if let Some(help) = def.get("description").and_then(Value::as_str) {
            self.out.push_str(&format!("# {}\n", first_sentence(help)));
        }
        let brackets = if array { ("[[", "]]") } else { ("[", "]") };
        self.out.push_str(&format!("{c}{}{path}{}\n", brackets.0, brackets.1));
        let Some(props) = def.get("properties").and_then(Value::as_object) else { return };
        let props = self.sorted(path, props);
        let required: Vec<&str> = def
            .get("required")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
            .filter_map(Value::as_str)
            .collect();
        let mut subsections = Vec::new();
        for (name, prop) in props {
            if let Some(sub) = subsection(self.schema, prop) {
                subsections.push((name, sub));
                continue;
            }
            self.field(&format!("{path}.{name}"), name, prop, optional, required.contains(&name.as_str()));
        }
        for (name, (def, array)) in subsections {
            self.section(&format!("{path}.{name}"), def, true, array);
        }
    }

    /// The properties of the section `path` in written order (those a written config leaves out
    /// after, by name).
    fn sorted<'p>(
        &self,
        path: &str,
        props: &'p serde_json::Map<String, Value>,
    ) -> Vec<(&'p String, &'p Value)> {
        let rank = |name: &str| {
            let full = if path.is_empty() { name.to_string() } else { format!("{path}.{name}") };
            self.order.iter().position(|o| *o == full).unwrap_or(usize::MAX)
        };
        let mut v: Vec<(&String, &Value)> = props.iter().collect();
        v.sort_by_key(|(name, _)| (rank(name), name.to_string()));
        v
    }

    /// One field: its help, then `name = default` (commented out when it or its section is
    /// unset by default).
    fn field(&mut self, path: &str, name: &str, prop: &Value, in_optional: bool, required: bool) {
        let choice = resolve(self.schema, prop);
        let help = prop
            .get("description")
            .or_else(|| choice?.get("description"))
            .and_then(Value::as_str)
            .map(first_sentence)
            .unwrap_or_default();
        let choices = choice.map(choice_values).unwrap_or_default();
        let mut line = help;
        if !choices.is_empty() {
            let list: Vec<String> = choices.iter().map(|v| v.to_string()).collect();
            line = format!("{line} One of {}.", list.join(", ")).trim().to_string();
        }
        let default = prop.get("default").cloned().or_else(|| found_default(path, prop, &choices));
        let (c, value) = match default {
            Some(Value::Null) | None if required => ("# ", "(required)".to_string()),
            Some(Value::Null) | None => ("# ", "(unset)".to_string()),
            Some(v) => (if in_optional { "# " } else { "" }, toml_value(&v)),
        };
        if !line.is_empty() {
            self.out.push_str(&format!("# {line}\n"));
        }
        self.out.push_str(&format!("{c}{name} = {value}\n"));
    }
}

/// The definition of a field that is a section of its own (a struct, optional or a list), and
/// whether it is a list of them.
fn subsection<'a>(schema: &'a Value, prop: &'a Value) -> Option<(&'a Value, bool)> {
    let def = resolve(schema, prop)?;
    let is_struct = def.get("properties").is_some();
    is_struct.then(|| (def, prop.get("items").is_some()))
}

/// The values of a choice (`oneOf` of constants, or `enum`).
fn choice_values(def: &Value) -> Vec<Value> {
    if let Some(e) = def.get("enum").and_then(Value::as_array) {
        return e.clone();
    }
    def.get("oneOf")
        .and_then(Value::as_array)
        .map(|v| v.iter().filter_map(|c| c.get("const").cloned()).collect())
        .unwrap_or_default()
}

/// The default of a field the default config's TOML leaves out: the candidate value that,
/// read into a config, gives the default config (`None`: none does, the field is unset).
fn found_default(path: &str, prop: &Value, choices: &[Value]) -> Option<Value> {
    let types: Vec<&str> = match prop.get("type") {
        Some(Value::String(t)) => vec![t.as_str()],
        Some(Value::Array(ts)) => ts.iter().filter_map(Value::as_str).collect(),
        _ => Vec::new(),
    };
    if types.contains(&"null") || prop.get("anyOf").is_some() {
        return None; // optional: unset by default
    }
    let mut candidates = choices.to_vec();
    candidates.extend(match types.first().copied() {
        Some("boolean") => vec![Value::Bool(false), Value::Bool(true)],
        Some("integer") => vec![Value::from(0), Value::from(1), Value::from(2)],
        Some("number") => vec![Value::from(0.0)],
        Some("array") => vec![Value::Array(Vec::new())],
        _ => Vec::new(),
    });
    let (section, name) = path.rsplit_once('.')?;
    let default = Config::default();
    candidates.into_iter().find(|v| {
        let text = format!("[{section}]\n{name} = {}\n", toml_value(v));
        Config::from_toml_str(&text, std::path::Path::new("probe")).is_ok_and(|c| c == default)
    })
}

/// A JSON value as a TOML value (inline).
fn toml_value(v: &Value) -> String {
    match v {
        Value::Array(items) => format!("[{}]", items.iter().map(toml_value).collect::<Vec<_>>().join(", ")),
        Value::Number(n) if n.is_f64() => {
            let f = n.as_f64().expect("a float");
            if f.fract() == 0.0 && f.abs() < 1e15 {
                format!("{f:.1}")
            } else {
                format!("{f}")
            }
        }
        Value::Object(m) => {
            let fields: Vec<String> = m.iter().map(|(k, v)| format!("{k} = {}", toml_value(v))).collect();
            format!("{{ {} }}", fields.join(", "))
        }
        other => other.to_string(),
    }
}

/// The first sentence of a doc comment on one line, its rustdoc link brackets removed.
fn first_sentence(doc: &str) -> String {
    let para = doc.split("\n\n").next().unwrap_or_default().replace('\n', " ");
    let end = para.find(". ").map_or(para.len(), |i| i + 1);
    let mut s = para[..end].to_string();
    // [`X`] and [`X`](path) -> `X`
    while let Some(open) = s.find("[`") {
        let Some(close) = s[open..].find("`]").map(|i| open + i) else { break };
        let mut after = close + 2;
        if s[after..].starts_with('(') {
            after = s[after..].find(')').map_or(after, |i| after + i + 1);
        }
        s = format!("{}{}{}", &s[..open], &s[open + 1..close + 1], &s[after..]);
    }
    s
}

#[cfg(test)]
mod tests;
