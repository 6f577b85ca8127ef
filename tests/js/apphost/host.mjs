// A minimal MCP Apps host for the browser tests: the official MCP client connects to
// rwt's /mcp, and ext-apps' AppBridge renders the robot app as hosts do: the tool's
// ui:// resource in a sandboxed frame under the CSP the resource declares, the tool's
// input and result handed to it, its tools/call requests carried to the server.
import { Client, StreamableHTTPClientTransport } from "@modelcontextprotocol/client";
import {
  AppBridge,
  PostMessageTransport,
  RESOURCE_MIME_TYPE,
  getToolUiResourceUri,
} from "@modelcontextprotocol/ext-apps/app-bridge";

const HOST = { name: "rwt-test-host", version: "1.0.0" };

// The frame's Content-Security-Policy from the resource's _meta.ui.csp (MCP Apps: the
// host allows the declared origins and nothing else).
function policy(csp) {
  const connect = (csp && csp.connectDomains) || [];
  const resources = (csp && csp.resourceDomains) || [];
  return [
    "default-src 'none'",
    "script-src 'unsafe-inline'",
    "style-src 'unsafe-inline'",
    `connect-src ${connect.join(" ") || "'none'"}`,
    `img-src ${[...resources, "data:"].join(" ")}`,
    `media-src ${[...resources, "blob:", "mediastream:"].join(" ")}`,
  ].join("; ");
}

window.showRobotApp = async ({ endpoint, token, args }) => {
  const state = (window.host = { calls: [], errors: [] });
  const client = new Client(HOST);
  const headers = token ? { Authorization: `Bearer ${token}` } : {};
  await client.connect(new StreamableHTTPClientTransport(new URL(endpoint), { requestInit: { headers } }));
  const { tools } = await client.listTools();
  const tool = tools.find((t) => t.name === "robot_app");
  const uri = getToolUiResourceUri(tool);
  const read = await client.readResource({ uri });
  const app = read.contents[0];
  if (app.mimeType !== RESOURCE_MIME_TYPE) throw new Error(`not an app: ${app.mimeType}`);
  const result = await client.callTool({ name: "robot_app", arguments: args });
  state.uri = uri;
  state.meta = app._meta;
  state.result = result;

  const frame = document.createElement("iframe");
  frame.id = "app";
  frame.sandbox = "allow-scripts";  // the app runs in an opaque origin of its own
  frame.width = "720";
  frame.height = "420";
  document.body.append(frame);
  const bridge = new AppBridge(client, HOST, { serverTools: {}, serverResources: {}, logging: {} });
  bridge.oninitialized = () => {
    state.initialized = true;
    bridge.sendToolInput({ arguments: args });
    bridge.sendToolResult(result);
  };
  bridge.addEventListener("sizechange", (size) => { state.size = size; });
  state.bridge = bridge;
  await bridge.connect(new PostMessageTransport(frame.contentWindow, frame.contentWindow));
  const csp = `<meta http-equiv="Content-Security-Policy" content="${policy(app._meta?.ui?.csp)}">`;
  frame.srcdoc = app.text.replace("<head>", `<head>${csp}`);
  return uri;
};

window.closeRobotApp = async () => {
  await window.host.bridge.teardownResource({});
  return true;
};
