// The parts of three.js the viewer uses, as one classic script (window.THREE), so that an exported
// page works when opened from disk: browsers refuse ES module imports over file://.
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";

window.THREE = Object.assign({}, THREE, { GLTFLoader, OrbitControls });
