use anyhow::Result;

#[derive(clap::Args)]
#[command(
    after_help = "Example:\n  stagerl config > my.toml    # edit, then: stagerl train --config my.toml"
)]
pub struct Args {
    /// `toml`: every section and field with its default and one line of help (the optional ones
    /// commented out), itself a valid config; `json-schema`: the config's JSON Schema, for editors.
    #[arg(long, default_value = "toml", value_parser = ["toml", "json-schema"])]
    format: String,
}

pub fn run(args: Args) -> Result<()> {
    match args.format.as_str() {
        "json-schema" => {
            let schema = stagerl::config::schema::json_schema();
            crate::out::text(&format!("{}\n", serde_json::to_string_pretty(&schema)?))
        }
        _ => crate::out::text(&stagerl::config::schema::annotated_toml()),
    }
}
