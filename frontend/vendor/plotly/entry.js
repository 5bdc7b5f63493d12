// The traces the dashboard draws (grep frontend/js for `type: "…"`): scatter (in core:
// lines, markers, filled bands), bar, scatterpolar (the sky map). Add a trace here and
// rerun build.sh if a page needs another one.
var Plotly = require("plotly.js/lib/core");

Plotly.register([
  require("plotly.js/lib/bar"),
  require("plotly.js/lib/scatterpolar"),
]);

module.exports = Plotly;
