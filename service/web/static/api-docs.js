// Starts Swagger UI on the API's documentation page (/api/v1/docs) with the OpenAPI document the
// page names (its #swagger-ui element's data-openapi-url). A file of its own, not an inline
// script, so that the page runs under a Content-Security-Policy of `script-src 'self'`.
// Nothing leaves the machine: no validator badge (it would send the document to a public
// validator), no fetch but the document itself.
"use strict";

document.addEventListener("DOMContentLoaded", () => {
  const root = document.getElementById("swagger-ui");
  window.ui = SwaggerUIBundle({
    url: root.dataset.openapiUrl,
    dom_id: "#swagger-ui",
    validatorUrl: null,
    deepLinking: true,
    displayOperationId: true,
    showExtensions: true,
    showCommonExtensions: true,
    presets: [SwaggerUIBundle.presets.apis, SwaggerUIBundle.SwaggerUIStandalonePreset],
    layout: "BaseLayout",
  });
});
